//! An interactive viewer: a scene in a window, running in real time.
//!
//! ```text
//! cargo run --release --example viewer -- scenes/drape_sphere.ron
//! ```
//!
//! Mouse: drag a particle with the left button (drag empty space to orbit), orbit with the
//! right button, zoom with the wheel. Keys: Space pause, S (or →) one frame while paused,
//! R reset, W wireframe, C strain colours, Esc quit. Frame time and diagnostics are in the
//! title bar. Saving the RON file reloads the scene; a broken file keeps the running scene and
//! shows the error in the title (and on stderr) instead of crashing.
//!
//! `--quit-after N` closes the window after N frames (a smoke test under a virtual display).
//! `--headless N` needs no window: it drives the same controls through a scripted session of N
//! frames (strain colours, a particle dragged and let go, pause and step, wireframe, a broken
//! then fixed hot reload of a copy of the scene), renders offscreen and writes the last frame to
//! `--out` (default `target/viewer.png`). CI runs it on Mesa's lavapipe.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Instant, SystemTime};

use glam::{Vec2, Vec3};
use harmonic::render::{Camera, Offscreen, Renderer, Style};
use harmonic::{Scene, Simulation};

/// The viewer's state and controls, apart from any window.
struct App {
    path: PathBuf,
    sim: Simulation,
    home: Camera,
    camera: Camera,
    style: Style,
    paused: bool,
    /// The last reload's error, shown until a reload succeeds.
    error: Option<String>,
    modified: Option<SystemTime>,
    drag: Option<Drag>,
    frame_ms: f64,
    /// Where between its last two steps the last frame left the simulation.
    alpha: f64,
}

enum Drag {
    /// A particle held on the plane through its start, facing the camera.
    Particle {
        index: usize,
        origin: Vec3,
        normal: Vec3,
    },
    Orbit {
        last: Vec2,
    },
}

fn load(path: &Path) -> Result<Simulation, String> {
    let scene = Scene::load(path).map_err(|e| e.to_string())?;
    Simulation::from_scene(&scene).map_err(|e| e.to_string())
}

fn modified(path: &Path) -> Option<SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

impl App {
    fn new(path: PathBuf) -> Result<Self, String> {
        let sim = load(&path)?;
        let home = Camera::of(&sim, 0.1);
        Ok(Self {
            modified: modified(&path),
            path,
            sim,
            home,
            camera: home,
            style: Style::default(),
            paused: false,
            error: None,
            drag: None,
            frame_ms: 0.0,
            alpha: 1.0,
        })
    }

    /// Reloads when the file changed since the last look; a failed reload keeps the scene.
    fn watch(&mut self) {
        let now = modified(&self.path);
        if now == self.modified {
            return;
        }
        self.modified = now;
        self.reload();
    }

    fn reload(&mut self) {
        match load(&self.path) {
            Ok(sim) => {
                self.sim = sim;
                self.drag = None;
                self.error = None;
            }
            Err(e) => {
                eprintln!("reload failed, the previous scene keeps running:\n{e}");
                self.error = Some(e);
            }
        }
    }

    /// One displayed frame of `frame_dt` seconds: the fixed-step accumulator, unless paused.
    fn update(&mut self, frame_dt: f64) {
        self.watch();
        if self.paused {
            return;
        }
        let t = Instant::now();
        match self.sim.advance(frame_dt) {
            Ok(a) => self.alpha = a.alpha,
            Err(e) => {
                self.error = Some(format!("stopped: {e}"));
                self.paused = true;
            }
        }
        self.frame_ms = 1e3 * t.elapsed().as_secs_f64();
    }

    fn key(&mut self, key: &str) -> bool {
        match key {
            " " => self.paused = !self.paused,
            "s" | "right" if self.paused => {
                if let Err(e) = self.sim.step() {
                    self.error = Some(format!("stopped: {e}"));
                }
            }
            "r" => {
                self.reload();
                self.camera = self.home;
            }
            "w" => self.style.wireframe = !self.style.wireframe,
            "c" => self.style.strain = !self.style.strain,
            "escape" | "q" => return false,
            _ => {}
        }
        true
    }

    /// Button down at `ndc` (−1..1, y up): grab the particle under the cursor, else orbit.
    fn press(&mut self, ndc: Vec2, aspect: f32, grab: bool) {
        let (origin, dir) = self.camera.ray(ndc, aspect);
        let reach = 0.03 * self.camera.distance;
        let nearest = grab
            .then(|| {
                self.sim
                    .positions()
                    .iter()
                    .enumerate()
                    .map(|(i, x)| {
                        let p = x.as_vec3() - origin;
                        let along = p.dot(dir);
                        (i, (p - along * dir).length(), along)
                    })
                    .filter(|&(_, off, along)| off < reach && along > 0.0)
                    .min_by(|a, b| a.2.total_cmp(&b.2))
            })
            .flatten();
        self.drag = Some(match nearest {
            Some((index, _, _)) => Drag::Particle {
                index,
                origin: self.sim.positions()[index].as_vec3(),
                normal: -dir,
            },
            None => Drag::Orbit { last: ndc },
        });
    }

    fn moved(&mut self, ndc: Vec2, aspect: f32) {
        match &mut self.drag {
            Some(Drag::Particle {
                index,
                origin,
                normal,
            }) => {
                let (o, d) = self.camera.ray(ndc, aspect);
                let denom = d.dot(*normal);
                if denom.abs() > 1e-6 {
                    let t = (*origin - o).dot(*normal) / denom;
                    let target = (o + t * d).as_dvec3();
                    if let Err(e) = self.sim.grab(*index, target) {
                        self.error = Some(e.to_string());
                    }
                }
            }
            Some(Drag::Orbit { last }) => {
                let delta = ndc - *last;
                *last = ndc;
                self.camera.yaw -= 2.0 * delta.x;
                self.camera.pitch = (self.camera.pitch - 1.5 * delta.y).clamp(-1.5, 1.5);
            }
            None => {}
        }
    }

    fn release(&mut self) {
        if let Some(Drag::Particle { index, .. }) = self.drag.take() {
            let _ = self.sim.release(index);
        }
    }

    fn zoom(&mut self, steps: f32) {
        self.camera.distance = (self.camera.distance * 0.9f32.powf(steps)).max(0.05);
    }

    fn title(&self) -> String {
        let d = self.sim.diagnostics();
        let mut t = format!(
            "harmonic viewer: {} | t {:.2} s | step {:.1} ms | max strain {:.2} % | energy {:.4e} J | h/h_c {:.3} | non-finite {}",
            self.path.display(),
            self.sim.time(),
            self.frame_ms,
            100.0 * d.max_strain,
            d.energy,
            d.step_ratio,
            d.non_finite
        );
        if self.paused {
            t.push_str(" | paused");
        }
        if let Some(e) = &self.error {
            t.push_str(" | ERROR: ");
            t.push_str(e.lines().next().unwrap_or(""));
        }
        t
    }
}

/// The scripted session of `--headless`: every control once, checked as it goes.
fn headless(scene: &Path, frames: u32, out: &Path) -> Result<(), String> {
    // Hot reload is exercised on a copy, so the shipped file is never touched.
    let copy = std::env::temp_dir().join(format!("harmonic-viewer-{}.ron", std::process::id()));
    let text = std::fs::read_to_string(scene).map_err(|e| format!("{}: {e}", scene.display()))?;
    std::fs::write(&copy, &text).map_err(|e| e.to_string())?;
    let result = session(&copy, &text, frames, out);
    let _ = std::fs::remove_file(&copy);
    result
}

fn session(copy: &Path, text: &str, frames: u32, out: &Path) -> Result<(), String> {
    let (w, h) = (480, 320);
    let aspect = w as f32 / h as f32;
    let mut app = App::new(copy.to_path_buf())?;
    let mut off = Offscreen::new(w, h).map_err(|e| e.to_string())?;
    let frames = frames.max(12);
    let mut image = None;
    let touch = |app: &mut App, body: &str| -> Result<(), String> {
        std::fs::write(copy, body).map_err(|e| e.to_string())?;
        // File times can be coarse: force the next look to see a change.
        app.modified = None;
        Ok(())
    };
    for k in 0..frames {
        match k {
            1 => {
                app.key("c");
            }
            2 => {
                // Grab whatever particle is nearest the picture's centre and lift it.
                let centre = app
                    .sim
                    .positions()
                    .iter()
                    .map(|x| x.as_vec3())
                    .sum::<Vec3>()
                    / app.sim.positions().len().max(1) as f32;
                let c = app.camera.view_proj(aspect).project_point3(centre);
                app.press(Vec2::new(c.x, c.y), aspect, true);
                if !matches!(app.drag, Some(Drag::Particle { .. })) {
                    return Err("no particle under the cursor at the cloth's centre".into());
                }
                app.moved(Vec2::new(c.x, c.y + 0.2), aspect);
            }
            5 => {
                let Some(Drag::Particle { index, .. }) = app.drag else {
                    return Err("the drag ended early".into());
                };
                let y = app.sim.positions()[index].y;
                app.release();
                println!("dragged particle {index} to y = {y:.3} m and let go");
            }
            6 => {
                app.key(" ");
                let t = app.sim.time();
                app.key("s");
                if app.sim.time() <= t {
                    return Err("a step while paused did not advance".into());
                }
                app.key(" ");
            }
            7 => {
                app.key("w");
                touch(&mut app, "Scene(")?;
            }
            8 => {
                if app.error.is_none() {
                    return Err("a broken scene file reloaded without an error".into());
                }
                println!(
                    "broken reload kept the scene: {}",
                    app.error
                        .as_deref()
                        .unwrap_or("")
                        .lines()
                        .next()
                        .unwrap_or("")
                );
                touch(&mut app, text)?;
            }
            9 => {
                if let Some(e) = &app.error {
                    return Err(format!("the fixed scene did not reload: {e}"));
                }
            }
            _ => {}
        }
        app.update(1.0 / 60.0);
        app.zoom(0.0);
        if k + 1 == frames {
            image = Some(
                off.capture(&mut app.sim, &app.camera, &app.style)
                    .map_err(|e| e.to_string())?,
            );
        }
    }
    println!("{}", app.title());
    let image = image.ok_or("no frame rendered")?;
    if image.distinct_colours() < 50 {
        return Err("the last frame is blank".into());
    }
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    }
    image.write_png(out).map_err(|e| e.to_string())?;
    println!("wrote {}", out.display());
    Ok(())
}

mod window {
    use super::*;
    use winit::application::ApplicationHandler;
    use winit::dpi::{LogicalSize, PhysicalPosition};
    use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
    use winit::event_loop::ActiveEventLoop;
    use winit::keyboard::{Key, NamedKey};
    use winit::window::{Window, WindowId};

    struct Gfx {
        window: Arc<Window>,
        surface: wgpu::Surface<'static>,
        config: wgpu::SurfaceConfiguration,
        renderer: Renderer,
    }

    pub struct Viewer {
        pub app: App,
        gfx: Option<Gfx>,
        cursor: PhysicalPosition<f64>,
        last: Instant,
        failed: Option<String>,
        /// Close after this many frames (a smoke test under a virtual display).
        pub quit_after: Option<u32>,
        frames: u32,
    }

    impl Viewer {
        pub fn new(app: App) -> Self {
            Self {
                app,
                gfx: None,
                cursor: PhysicalPosition::new(0.0, 0.0),
                last: Instant::now(),
                failed: None,
                quit_after: None,
                frames: 0,
            }
        }

        pub fn failure(&self) -> Option<&str> {
            self.failed.as_deref()
        }

        fn ndc(&self) -> (Vec2, f32) {
            let Some(g) = &self.gfx else {
                return (Vec2::ZERO, 1.0);
            };
            let (w, h) = (g.config.width.max(1) as f32, g.config.height.max(1) as f32);
            let p = Vec2::new(
                2.0 * self.cursor.x as f32 / w - 1.0,
                1.0 - 2.0 * self.cursor.y as f32 / h,
            );
            (p, w / h)
        }

        fn start(&mut self, el: &ActiveEventLoop) -> Result<Gfx, String> {
            let window = Arc::new(
                el.create_window(
                    Window::default_attributes()
                        .with_title("harmonic viewer")
                        .with_inner_size(LogicalSize::new(1024.0, 720.0)),
                )
                .map_err(|e| e.to_string())?,
            );
            let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle(
                Box::new(el.owned_display_handle()),
            ));
            let surface = instance
                .create_surface(window.clone())
                .map_err(|e| e.to_string())?;
            let adapter =
                pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::HighPerformance,
                    force_fallback_adapter: false,
                    compatible_surface: Some(&surface),
                    apply_limit_buckets: false,
                }))
                .map_err(|e| e.to_string())?;
            let (device, queue) =
                pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))
                    .map_err(|e| e.to_string())?;
            let size = window.inner_size();
            let mut config = surface
                .get_default_config(&adapter, size.width.max(1), size.height.max(1))
                .ok_or("the window's surface is not supported by the adapter")?;
            // The shader writes display colours: prefer a format without sRGB conversion.
            let caps = surface.get_capabilities(&adapter);
            if let Some(f) = caps.formats.iter().find(|f| !f.is_srgb()) {
                config.format = *f;
            }
            surface.configure(&device, &config);
            let ctx = Arc::new(harmonic::internals::gpu::GpuContext::from_device(
                device,
                queue,
                adapter.get_info(),
                adapter.limits(),
            ));
            let renderer = Renderer::new(ctx, config.format).map_err(|e| e.to_string())?;
            Ok(Gfx {
                window,
                surface,
                config,
                renderer,
            })
        }

        fn redraw(&mut self) {
            let now = Instant::now();
            let dt = (now - self.last).as_secs_f64();
            self.last = now;
            self.app.update(dt);
            let Some(g) = &mut self.gfx else { return };
            g.window.set_title(&self.app.title());
            let frame = match g.surface.get_current_texture() {
                wgpu::CurrentSurfaceTexture::Success(f)
                | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
                wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                    g.surface.configure(&g.renderer.context().device, &g.config);
                    return;
                }
                _ => return,
            };
            let view = frame.texture.create_view(&Default::default());
            let alpha = if self.app.paused { 1.0 } else { self.app.alpha };
            if let Err(e) = g.renderer.draw(
                &mut self.app.sim,
                alpha,
                None,
                &self.app.camera,
                &self.app.style,
                &view,
                (g.config.width, g.config.height),
            ) {
                self.app.error = Some(e.to_string());
            }
            g.renderer.context().queue.present(frame);
        }
    }

    impl ApplicationHandler for Viewer {
        fn resumed(&mut self, el: &ActiveEventLoop) {
            if self.gfx.is_some() {
                return;
            }
            match self.start(el) {
                Ok(g) => {
                    g.window.request_redraw();
                    self.gfx = Some(g);
                    self.last = Instant::now();
                }
                Err(e) => {
                    self.failed = Some(e);
                    el.exit();
                }
            }
        }

        fn window_event(&mut self, el: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
            match event {
                WindowEvent::CloseRequested => el.exit(),
                WindowEvent::Resized(size) => {
                    if let Some(g) = &mut self.gfx {
                        g.config.width = size.width.max(1);
                        g.config.height = size.height.max(1);
                        g.surface.configure(&g.renderer.context().device, &g.config);
                    }
                }
                WindowEvent::RedrawRequested => {
                    self.redraw();
                    self.frames += 1;
                    if self.quit_after.is_some_and(|n| self.frames >= n) {
                        println!("{} frames shown; {}", self.frames, self.app.title());
                        el.exit();
                        return;
                    }
                    if let Some(g) = &self.gfx {
                        g.window.request_redraw();
                    }
                }
                WindowEvent::KeyboardInput { event, .. } if event.state.is_pressed() => {
                    let key = match &event.logical_key {
                        Key::Named(NamedKey::Space) => " ".to_string(),
                        Key::Named(NamedKey::Escape) => "escape".to_string(),
                        Key::Named(NamedKey::ArrowRight) => "right".to_string(),
                        Key::Character(c) => c.to_lowercase(),
                        _ => String::new(),
                    };
                    if !self.app.key(&key) {
                        el.exit();
                    }
                }
                WindowEvent::CursorMoved { position, .. } => {
                    self.cursor = position;
                    let (p, aspect) = self.ndc();
                    self.app.moved(p, aspect);
                }
                WindowEvent::MouseInput { state, button, .. } => {
                    let (p, aspect) = self.ndc();
                    match (state, button) {
                        (ElementState::Pressed, MouseButton::Left) => {
                            self.app.press(p, aspect, true)
                        }
                        (ElementState::Pressed, MouseButton::Right) => {
                            self.app.press(p, aspect, false)
                        }
                        (ElementState::Released, _) => self.app.release(),
                        _ => {}
                    }
                }
                WindowEvent::MouseWheel { delta, .. } => {
                    let steps = match delta {
                        MouseScrollDelta::LineDelta(_, y) => y,
                        MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                    };
                    self.app.zoom(steps);
                }
                _ => {}
            }
        }
    }
}

fn main() -> std::process::ExitCode {
    let mut args = std::env::args().skip(1);
    let mut scene = PathBuf::from("scenes/drape_sphere.ron");
    let mut headless_frames = None;
    let mut out = PathBuf::from("target/viewer.png");
    let mut quit_after = None;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--headless" => headless_frames = args.next().and_then(|n| n.parse::<u32>().ok()),
            "--out" => out = args.next().map(PathBuf::from).unwrap_or(out),
            "--quit-after" => quit_after = args.next().and_then(|n| n.parse::<u32>().ok()),
            _ => scene = PathBuf::from(a),
        }
    }
    let result = match headless_frames {
        Some(frames) => headless(&scene, frames, &out),
        None => App::new(scene).and_then(|app| {
            let event_loop = winit::event_loop::EventLoop::new()
                .map_err(|e| format!("no window system ({e}); `--headless N` runs without one"))?;
            let mut viewer = window::Viewer::new(app);
            viewer.quit_after = quit_after;
            event_loop.run_app(&mut viewer).map_err(|e| e.to_string())?;
            viewer.failure().map_or(Ok(()), |e| Err(e.to_string()))
        }),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::from(2)
        }
    }
}
