//! Not API: the lab's (`benches/lab`) and the integration tests' window into the engine's
//! internals. Hidden from the docs and outside any semver promise; a game uses the crate root.

#![allow(missing_docs)]

use crate::scene::{Anchor, Cloth, Plane, Scene, SpringSpec};

pub use crate::buffers::{GatherOptions, Packed, PackedGrid, PackedSpring};
pub use crate::error::Readable;
pub use crate::integrate::Solver;

/// Packed buffers: the flat state and topology the kernels run on.
pub mod buffers {
    pub use crate::buffers::*;
}
/// The integrators' kernels.
pub mod integrate {
    pub use crate::integrate::*;
}
/// The energy audit's books over packed buffers.
pub mod audit {
    pub use crate::audit::{Auditor, DamperLaw, ProjectionLines};
}
/// Diagnostics over packed buffers.
pub mod metrics {
    pub use crate::metrics::*;
}
/// Automatic substeps.
pub mod step_control {
    pub use crate::step_control::*;
}
/// Rigid props: kinematic paths.
pub mod contacts {
    pub use crate::contacts::path_pose;
}
/// The GPU back end.
#[cfg(feature = "gpu")]
pub mod gpu {
    pub use crate::gpu::*;
}

/// For a headless binary's `main`, before any thread starts: Mesa's Vulkan device-select layer
/// probes for a Wayland display while adapters are listed, and libwayland prints an error where
/// there is no session (no `XDG_RUNTIME_DIR`), on every headless render. The engine ranks the
/// adapters itself, so the layer is switched off there (`NODEVICE_SELECT=1`) unless the
/// environment says otherwise. Sets an environment variable: not for a library's callers.
pub fn quiet_headless_adapters() {
    let unset = |k: &str| std::env::var_os(k).is_none();
    if unset("XDG_RUNTIME_DIR") && unset("NODEVICE_SELECT") {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
}

/// An `n`×`n` hanging cloth, 1 kg over 1 m × 1 m, structural + shear + bend, pinned at the two
/// top corners (128×128: 16,384 particles, 97,026 springs).
pub fn hanging_cloth(n: u32) -> Scene {
    let spec = |k: f64| SpringSpec {
        stiffness: Some(k),
        damping: Some(0.01),
        ..Default::default()
    };
    Scene {
        name: Some(format!("hanging cloth {n}×{n}")),
        substeps: Some(1),
        gravity: [0.0, -9.81, 0.0],
        cloths: vec![Cloth {
            origin: [-0.5, 1.0, 0.0],
            size: (1.0, 1.0),
            resolution: (n, n),
            plane: Plane::Vertical,
            mass: 1.0,
            structural: spec(1e3),
            shear: Some(spec(1e3)),
            bend: Some(spec(1e2)),
            pins: vec![Anchor::TopLeft, Anchor::TopRight],
            velocity: [0.0; 3],
            air: None,
            tethers: None,
            stretch_limit: None,
            tearing: None,
            self_collision: None,
        }],
        ..Scene::new(1e-4)
    }
}

/// `k` copies of [`hanging_cloth`] side by side, 1.5 m apart (many small cloths: capes, flags).
pub fn hanging_cloths(n: u32, k: u32) -> Scene {
    let mut scene = hanging_cloth(n);
    let one = scene.cloths[0].clone();
    scene.cloths = (0..k)
        .map(|i| Cloth {
            origin: [one.origin[0] + 1.5 * i as f64, one.origin[1], one.origin[2]],
            ..one.clone()
        })
        .collect();
    if k > 1 {
        scene.name = Some(format!("{k} hanging cloths {n}×{n}"));
    }
    scene
}
