//! The GPU back end's shaders, without an adapter: every shader as assembled (the prelude joined
//! before each step shader) parses and validates, the embedded sources are the files, and the
//! Rust mirrors are laid out like the WGSL structs.
#![cfg(feature = "gpu")]

use std::mem::{offset_of, size_of};
use std::path::{Path, PathBuf};

use harmonic::internals::gpu;

fn shader_files() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("shaders/ exists")
        .map(|e| e.expect("readable entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no WGSL files in {}", dir.display());
    files
}

/// The step's shaders, which the prelude goes before.
const STEP_SHADERS: [&str; 6] = [
    "integrate.wgsl",
    "contacts.wgsl",
    "tethers.wgsl",
    "air.wgsl",
    "collide.wgsl",
    "collide_pass.wgsl",
];

/// Self-collision's shaders, which the triangle queries go before (after the prelude).
const TRIANGLE_SHADERS: [&str; 2] = ["collide.wgsl", "collide_pass.wgsl"];

/// A shader file as the engine assembles it: the prelude first for a step shader, then the
/// triangle queries for self-collision's.
fn assembled(name: &str) -> String {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).expect("readable shader");
    if TRIANGLE_SHADERS.contains(&name) {
        read("prelude.wgsl") + &read("triangle.wgsl") + &read(name)
    } else if STEP_SHADERS.contains(&name) {
        read("prelude.wgsl") + &read(name)
    } else {
        read(name)
    }
}

fn parse(name: &str) -> naga::Module {
    let text = assembled(name);
    naga::front::wgsl::parse_str(&text)
        .unwrap_or_else(|e| panic!("{}", e.emit_to_string_with_path(&text, name)))
}

#[test]
fn every_shader_parses_and_validates() {
    let mut checked = 0;
    for path in shader_files() {
        let name = path.file_name().unwrap().to_str().unwrap();
        if name == "prelude.wgsl" {
            continue;
        }
        let module = parse(name);
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::default(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{name}: {e:?}"));
        checked += 1;
    }
    assert_eq!(
        checked, 8,
        "integrate, contacts, render, tethers, air, collide, collide_pass and triangle"
    );
}

#[test]
fn the_embedded_shaders_are_the_prelude_and_the_files() {
    assert_eq!(gpu::SHADER, assembled("integrate.wgsl"));
    assert_eq!(gpu::contacts::SHADER, assembled("contacts.wgsl"));
    assert_eq!(gpu::tethers::SHADER, assembled("tethers.wgsl"));
    assert_eq!(gpu::air::SHADER, assembled("air.wgsl"));
    assert_eq!(gpu::collide::SHADER, assembled("collide.wgsl"));
    assert_eq!(gpu::collide_pass::SHADER, assembled("collide_pass.wgsl"));
    assert!(gpu::SHADER.starts_with(gpu::PRELUDE));
    // One definition: no step shader declares what the prelude does.
    for name in STEP_SHADERS {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
        let own = std::fs::read_to_string(dir.join(name)).unwrap();
        for shared in [
            "struct Position",
            "override WORKGROUP",
            "fn linear(",
            "fn moved(",
        ] {
            assert!(!own.contains(shared), "{name} declares {shared} again");
        }
    }
}

/// Size and member offsets of the WGSL struct `name`, from naga's layout.
fn wgsl_layout(module: &naga::Module, name: &str) -> (u32, Vec<(String, u32)>) {
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).expect("layout");
    for (handle, ty) in module.types.iter() {
        if ty.name.as_deref() == Some(name) {
            if let naga::TypeInner::Struct { members, span } = &ty.inner {
                assert_eq!(layouter[handle].size, *span);
                let members = members
                    .iter()
                    .map(|m| (m.name.clone().unwrap_or_default(), m.offset))
                    .collect();
                return (*span, members);
            }
        }
    }
    panic!("struct {name} not in the shader");
}

macro_rules! check_layout {
    ($module:expr, $([$m:ident])? $ty:ident { $($field:ident),* $(,)? }) => {{
        let (size, members) = wgsl_layout($module, stringify!($ty));
        type Mirror = gpu::$($m::)?$ty;
        let rust: Vec<(String, u32)> = vec![
            $((stringify!($field).to_string(), offset_of!(Mirror, $field) as u32)),*
        ];
        assert_eq!(members, rust, "{}: member names and offsets", stringify!($ty));
        assert_eq!(size as usize, size_of::<Mirror>(), "{}: size", stringify!($ty));
    }};
}

#[test]
fn pod_mirrors_match_the_wgsl_layouts() {
    let module = parse("integrate.wgsl");
    check_layout!(
        &module,
        Params {
            gravity,
            h,
            particles,
            springs,
            one,
            _pad1
        }
    );
    check_layout!(&module, Position { hi, lo });
    check_layout!(&module, Coef { rest, p, q, wa });
    check_layout!(&module, Entry { spring, coef });
    check_layout!(
        &module,
        Range {
            start,
            count,
            cols,
            links,
            link_count,
            _pad0,
            _pad1,
            _pad2
        }
    );
    let contact_module = parse("contacts.wgsl");
    {
        check_layout!(
            &contact_module,
            [contacts] Step {
                h,
                thickness,
                restitution,
                particles,
                colliders,
                slot,
                groups,
                _pad
            }
        );
        check_layout!(
            &contact_module,
            [contacts] Collider {
                kind,
                dynamic,
                _pad0,
                _pad1,
                translation,
                rotation,
                dims,
                lin,
                ang,
                com,
                sphere
            }
        );
        check_layout!(
            &contact_module,
            [contacts] Partial {
                impulse,
                torque,
                support,
                support_torque
            }
        );
    }
    let tether_module = parse("tethers.wgsl");
    check_layout!(
        &tether_module,
        [tethers] TetherStep {
            gravity,
            h,
            parts,
            _pad0,
            _pad1,
            _pad2
        }
    );
    check_layout!(
        &tether_module,
        [tethers] Part {
            particle,
            first,
            count,
            _pad
        }
    );
    check_layout!(&tether_module, [tethers] Link { anchor, limit });
    let air_module = parse("air.wgsl");
    check_layout!(
        &air_module,
        [air] AirFrame {
            mean,
            strength,
            along,
            phase,
            keys,
            cell,
            triangles,
            particles,
            _pad0,
            _pad1
        }
    );
    check_layout!(&air_module, [air] Tri { a, b, c, cloth });
    let collide_module = parse("collide.wgsl");
    check_layout!(
        &collide_module,
        [collide] Find {
            cell,
            reach_max,
            slack,
            margin,
            members,
            triangles,
            buckets,
            capacity,
            tris_at,
            excluded_at,
            thickness_at,
            flags_at,
            queries,
            _pad0,
            _pad1,
            _pad2
        }
    );
    check_layout!(&collide_module, [collide] Centre { m, cell });
    let pass_module = parse("collide_pass.wgsl");
    check_layout!(&pass_module, [collide_pass] PassStep { particles, one, colours, settles });
    check_layout!(&pass_module, [collide_pass] Span { first, end, _pad0, _pad1 });
    check_layout!(
        &pass_module,
        [collide_pass] Contact {
            p,
            a,
            b,
            c,
            thickness,
            mu,
            mu_s,
            _pad
        }
    );
    check_layout!(&pass_module, [collide_pass] Active { n, weights });
    // The override constants the solver sets exist in the shader.
    let overrides: Vec<_> = module
        .overrides
        .iter()
        .filter_map(|(_, o)| o.name.clone())
        .collect();
    for name in ["WORKGROUP", "RATE", "PINS", "UPDATE", "GRIDS"] {
        assert!(
            overrides.iter().any(|o| o == name),
            "override {name} missing: {overrides:?}"
        );
    }
}

/// Every source path a shader names as its mirror (`src/…`) exists: a moved module takes its
/// shader's pointer with it.
#[test]
fn the_paths_the_shaders_name_exist() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut named = 0;
    for file in shader_files() {
        let text = std::fs::read_to_string(&file).unwrap();
        for (at, _) in text.match_indices("src/") {
            let path: String = text[at..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || matches!(c, '/' | '_' | '.' | '-'))
                .collect();
            let path = path.trim_end_matches('.');
            named += 1;
            assert!(
                root.join(path).exists(),
                "{} names {path}, which does not exist",
                file.display()
            );
        }
    }
    assert!(named >= 5, "{named} paths named");
}
