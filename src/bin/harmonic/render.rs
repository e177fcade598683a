//! `harmonic render`: a scene drawn headless to PNG, pictures evenly spaced over the run, and a
//! contact sheet filled as they arrive.

use super::*;

#[cfg(feature = "gpu")]
pub(super) fn render(args: RenderArgs) -> Result<(), String> {
    use harmonic::render::{Camera, Offscreen, Sheet, Style};
    let parse = |s: &str| s.trim().parse::<u32>().ok().filter(|&v| v > 0);
    let (width, height) = match args.size.split_once(['x', 'X']) {
        Some((w, h)) => parse(w).zip(parse(h)),
        None => None,
    }
    .filter(|&(w, h)| w <= 8192 && h <= 8192)
    .ok_or_else(|| {
        format!(
            "--size {}: expected WIDTHxHEIGHT, each a whole number of pixels from 1 to 8192, e.g. 800x600",
            args.size
        )
    })?;
    // Drawn in f32: a scale past its range would be drawn as infinite.
    let strain_scale = args.strain_scale as f32;
    if !(strain_scale.is_finite() && strain_scale > 0.0) {
        return Err(format!(
            "--strain-scale {:?}: expected the strain drawn fully red, finite and > 0, at most {:e} (0.1 is 10 %)",
            args.strain_scale,
            f32::MAX
        ));
    }
    if args.out.exists() && !args.out.is_dir() {
        return Err(format!(
            "--out {}: not a directory (a file of that name exists); name a folder",
            args.out.display()
        ));
    }
    let limits = args.limits.limits();
    let scene = Scene::load_with(&args.scene, &limits).map_err(|e| e.to_string())?;
    let mut sim = Simulation::from_scene_with(&scene, &limits).map_err(|e| e.to_string())?;
    let dt = sim.config().dt;
    let steps = frames(None, args.seconds, scene.seconds, sim.config(), &limits)?;
    let seconds = steps as f64 * dt;
    if args.frames == 0 || u64::from(args.frames) > steps {
        return Err(format!(
            "--frames {}: expected 1 to {steps} pictures (one per frame of the run at most)",
            args.frames
        ));
    }
    // The sheet is checked before the run and filled as each picture arrives.
    let mut sheet = args
        .sheet
        .then(|| {
            let columns = (f64::from(args.frames)).sqrt().ceil() as u32;
            Sheet::new((width, height), args.frames, columns)
        })
        .transpose()
        .map_err(|e| format!("--sheet: {e}: lower --size or --frames"))?;
    let mut offscreen = Offscreen::new(width, height).map_err(|e| e.to_string())?;
    say!(
        "render: {} on {}, {width}x{height}, {} picture(s) over {seconds} s",
        args.scene.display(),
        offscreen.renderer().context().describe(),
        args.frames
    );
    // The camera frames the scene as it starts (with a margin); it follows the scene's centre
    // (a walking character) and backs off when the scene spreads, never closing in.
    let first = Camera::of(&sim, 0.05);
    let style = Style {
        wireframe: args.wireframe,
        strain: args.strain,
        strain_scale,
    };
    std::fs::create_dir_all(&args.out).map_err(|e| format!("--out {}: {e}", args.out.display()))?;
    let stem = args
        .scene
        .file_stem()
        .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
    let mut bar = Progress::new(steps);
    let mut done = 0u64;
    for k in 1..=args.frames {
        let target = (steps as f64 * k as f64 / args.frames as f64).round() as u64;
        while done < target {
            let stats = *sim.step().map_err(|e| format!("run stopped: {e}"))?;
            done += 1;
            bar.set(done, sim.time());
            if let Some(f) = stats.failure {
                return Err(format!("run failed at {f}"));
            }
            if stats.quarantined > 0 {
                return Err(format!(
                    "run degraded at frame {done}: {} particle(s) went non-finite and were \
                     quarantined (a step too large for the scene, or a spring that degenerated \
                     to a point); `harmonic run` prints the details",
                    stats.quarantined
                ));
            }
        }
        let now = Camera::of(&sim, 0.05);
        let camera = Camera {
            distance: now.distance.max(first.distance),
            ..now
        };
        let image = offscreen
            .capture(&mut sim, &camera, &style)
            .map_err(|e| e.to_string())?;
        let path = args.out.join(format!("{stem}_{k:03}.png"));
        image.write_png(&path).map_err(|e| e.to_string())?;
        let line = format!(
            "wrote {} (t = {:.3} s, {} cloth pixel(s))",
            path.display(),
            sim.time(),
            image.cloth_pixels()
        );
        bar.println(line)?;
        if let Some(sheet) = sheet.as_mut() {
            sheet.place(k - 1, &image).map_err(|e| e.to_string())?;
        }
    }
    bar.finish();
    if let Some(sheet) = sheet {
        let path = args.out.join(format!("{stem}_sheet.png"));
        sheet.finish().write_png(&path).map_err(|e| e.to_string())?;
        say!("wrote {}", path.display());
    }
    Ok(())
}

#[cfg(not(feature = "gpu"))]
pub(super) fn render(_: RenderArgs) -> Result<(), String> {
    Err(harmonic::GpuError::NotBuilt.to_string())
}
