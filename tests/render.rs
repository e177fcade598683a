//! Headless rendering: every shipped scene draws a picture with its cloth in it, and the
//! cloth's pixels cover the area its triangles project to (an independent CPU projection).
//!
//! Skips only when no adapter at all exists; fails instead when `HARMONIC_REQUIRE_GPU` is set
//! (CI sets it: it has Mesa's lavapipe).
#![cfg(feature = "gpu")]

mod common;

use std::path::{Path, PathBuf};

use glam::Vec3;
use harmonic::prelude::*;
use harmonic::render::{Camera, Image, Offscreen, Style};

fn offscreen(width: u32, height: u32) -> Option<Offscreen> {
    common::gpu_or_skip(Offscreen::new(width, height))
}

fn shipped_scenes() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "ron"))
        .collect();
    files.sort();
    files
}

fn framed(sim: &Simulation) -> Camera {
    Camera::of(sim, 0.05)
}

#[test]
fn every_shipped_scene_renders_its_cloth() {
    let Some(mut off) = offscreen(200, 150) else {
        return;
    };
    let files = shipped_scenes();
    assert!(files.len() >= 10, "found {} scenes", files.len());
    let total = 200 * 150;
    for path in files {
        let mut sim = Simulation::load(&path).unwrap_or_else(|e| panic!("{e}"));
        // A quarter of a simulated second (at most 15 frames): the scene is under way.
        let frames = ((0.25 / sim.config().dt).ceil() as usize).clamp(1, 15);
        for _ in 0..frames {
            sim.step()
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
        let camera = framed(&sim);
        let image = off
            .capture(&mut sim, &camera, &Style::default())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let cloth = image.cloth_pixels();
        let sky = background_pixels(&image);
        // A blank picture has none; the smallest scene (four short falling chains in a wide
        // view) has a few dozen.
        assert!(
            cloth >= 20,
            "{}: {cloth} cloth pixels of {total}",
            path.display()
        );
        assert!(sky > 0, "{}: no background left", path.display());
        assert!(
            image.distinct_colours() > 50,
            "{}: flat picture",
            path.display()
        );
    }
}

/// Pixels of the clear colour: nothing drawn there.
fn background_pixels(image: &Image) -> usize {
    let sky = harmonic::render::SKY.map(|c| (c * 255.0).round() as i32);
    image
        .rgba
        .chunks_exact(4)
        .filter(|p| (0..3).all(|c| (p[c] as i32 - sky[c]).abs() <= 1))
        .count()
}

#[test]
fn cloth_pixels_cover_the_projected_area_of_its_triangles() {
    let (w, h) = (320u32, 240u32);
    let Some(mut off) = offscreen(w, h) else {
        return;
    };
    // A flat cloth, seen at t = 0: its triangles do not overlap on screen.
    let scene = Scene::parse(
        r#"Scene(
            dt: 0.01,
            cloths: [(origin: (-0.5, 1.0, -0.4), size: (1.0, 0.8), resolution: (21, 17),
                      plane: Horizontal, mass: 0.5, structural: (frequency: 30.0, damping_ratio: 0.1))],
        )"#,
        "flat.ron",
    )
    .unwrap();
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let camera = framed(&sim);
    let image = off.capture(&mut sim, &camera, &Style::default()).unwrap();
    let m = camera.view_proj(w as f32 / h as f32);
    let view = sim.render(1.0);
    let pixel = |p: Vec3| {
        let c = m.project_point3(p);
        glam::Vec2::new((c.x + 1.0) * 0.5 * w as f32, (1.0 - c.y) * 0.5 * h as f32)
    };
    let area: f32 = view
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| pixel(view.positions[i as usize]));
            0.5 * (b - a).perp_dot(c - a).abs()
        })
        .sum();
    let cloth = image.cloth_pixels() as f32;
    assert!(area > 2000.0, "the cloth projects to {area} pixels only");
    // Edge pixels are half cloth, half background: a rim's worth of slack.
    assert!(
        (cloth - area).abs() < 0.05 * area,
        "{cloth} cloth pixels against {area} projected"
    );
}

#[test]
fn bodies_are_drawn_where_they_are() {
    let (w, h) = (240u32, 180u32);
    let Some(mut off) = offscreen(w, h) else {
        return;
    };
    let scene =
        Scene::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/drape_sphere.ron")).unwrap();
    let mut sim = Simulation::from_scene(&scene).unwrap();
    let camera = framed(&sim);
    let image = off.capture(&mut sim, &camera, &Style::default()).unwrap();
    // The ball's centre (0, 0.5, 0) is under the cloth (seen from above) or in plain view:
    // either way the pixel there is not background, and a point well above everything is.
    let m = camera.view_proj(w as f32 / h as f32);
    let at = |p: Vec3| {
        let c = m.project_point3(p);
        assert!(c.x.abs() < 1.0 && c.y.abs() < 1.0, "{p} is off the picture");
        let x = ((c.x + 1.0) * 0.5 * w as f32) as u32;
        let y = ((1.0 - c.y) * 0.5 * h as f32) as u32;
        image.pixel(x, y)
    };
    let sky = harmonic::render::SKY.map(|c| (c * 255.0).round() as u8);
    let ball = at(Vec3::new(0.0, 0.5, 0.0));
    assert_ne!(&ball[..3], &sky[..], "nothing drawn at the ball");
    let above = at(Vec3::new(0.0, 1.6, 0.0));
    assert_eq!(&above[..3], &sky[..], "something drawn far above the scene");
}
