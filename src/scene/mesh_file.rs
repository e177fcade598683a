//! A mesh cloth's file beside the scene, read into its `vertices` and `triangles`: Wavefront
//! OBJ through `tobj`, glTF 2.0 (`.gltf` with `.bin` buffers beside it, or `.glb`) through
//! `gltf` without its image and import features.

use std::path::{Path, PathBuf};

use glam::{DMat4, DVec3};

use super::mesh::MeshCloth;
use crate::error::Issue;

impl MeshCloth {
    /// Its file's path, resolved against the scene's directory `dir`.
    pub fn file_path(&self, dir: &Path) -> Option<PathBuf> {
        self.file.as_ref().map(|f| dir.join(f))
    }

    /// Reads its `file` into `vertices` and `triangles` (`at` locates the problems: a file
    /// that cannot be read, of another format, past [`super::MAX_FILE_BYTES`] or that does not
    /// parse, or inline geometry beside it). Nothing to do without a file.
    pub(super) fn read_file(&mut self, dir: &Path, at: &str) -> Result<(), Issue> {
        let Some(path) = self.file_path(dir) else {
            return Ok(());
        };
        let issue = |message: String| Issue {
            location: format!("{at}.file"),
            message,
        };
        if !self.vertices.is_empty() || !self.triangles.is_empty() {
            return Err(issue(
                "give `file` or inline `vertices` and `triangles`, not both".into(),
            ));
        }
        let ext = (path.extension())
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("obj") => {
                let text = super::read_text(&path).map_err(|e| issue(e.to_string()))?;
                self.read_obj(&text).map_err(|e| {
                    issue(format!("{}: not a readable OBJ file ({e})", path.display()))
                })
            }
            Some("gltf" | "glb") => {
                let bytes = read_bytes(&path).map_err(issue)?;
                self.read_gltf(&bytes, path.parent().unwrap_or(Path::new("")))
                    .map_err(|e| issue(format!("{}: {e}", path.display())))
            }
            _ => Err(issue(format!(
                "{}: only Wavefront OBJ (.obj) and glTF 2.0 (.gltf, .glb) files are read",
                path.display()
            ))),
        }
    }

    /// Every object of an OBJ file, its faces triangulated; materials are not read (a cloth
    /// takes its material from the scene).
    fn read_obj(&mut self, text: &str) -> Result<(), tobj::LoadError> {
        let options = tobj::LoadOptions {
            triangulate: true,
            ignore_points: true,
            ignore_lines: true,
            ..Default::default()
        };
        let (models, _) = tobj::load_obj_buf(&mut text.as_bytes(), &options, |_| {
            Err(tobj::LoadError::GenericFailure)
        })?;
        for model in models {
            let m = &model.mesh;
            self.append(
                m.positions.chunks_exact(3).map(|p| [p[0], p[1], p[2]]),
                m.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]),
            );
        }
        Ok(())
    }

    /// A glTF file's first mesh: its triangle primitives, each placed by the world transform
    /// of the first node of the default scene (else of any scene) that instantiates the mesh
    /// (identity when none does). Buffers come from a `.glb`'s binary chunk or from files
    /// beside it; embedded base64 buffers are refused by name.
    fn read_gltf(&mut self, bytes: &[u8], dir: &Path) -> Result<(), String> {
        let gltf =
            gltf::Gltf::from_slice(bytes).map_err(|e| format!("not a readable glTF ({e})"))?;
        let mut buffers = Vec::new();
        for buffer in gltf.buffers() {
            let data = match buffer.source() {
                gltf::buffer::Source::Bin => gltf
                    .blob
                    .clone()
                    .ok_or("its buffer is the binary chunk, and it has none")?,
                gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                    return Err(
                        "an embedded (base64) buffer is not read: export as .glb, or with the \
                         .bin beside it"
                            .into(),
                    );
                }
                gltf::buffer::Source::Uri(uri) => read_bytes(&dir.join(uri))?,
            };
            if data.len() < buffer.length() {
                return Err(format!("buffer {} is shorter than it says", buffer.index()));
            }
            buffers.push(data);
        }
        let mesh = gltf.meshes().next().ok_or("it has no mesh")?;
        // The attributes its pins name, vertex by vertex alongside the positions.
        let names: Vec<String> = (self.pins.iter())
            .filter_map(|p| match p {
                super::mesh::MeshPin::Attribute(name, _) => Some(name.clone()),
                _ => None,
            })
            .collect();
        let mut values: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
        let place = node_transform(&gltf, mesh.index()).unwrap_or(DMat4::IDENTITY);
        for primitive in mesh.primitives() {
            if primitive.mode() != gltf::mesh::Mode::Triangles {
                continue;
            }
            let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| &d[..]));
            let positions: Vec<[f64; 3]> = reader
                .read_positions()
                .ok_or_else(|| format!("primitive {} has no positions", primitive.index()))?
                .map(|p| {
                    let p =
                        place.transform_point3(DVec3::new(p[0].into(), p[1].into(), p[2].into()));
                    p.to_array()
                })
                .collect();
            let n = positions.len() as u32;
            for (name, out) in names.iter().zip(&mut values) {
                let custom = name
                    .strip_prefix('_')
                    .map(|s| gltf::Semantic::Extras(s.into()));
                let accessor = custom.and_then(|s| primitive.get(&s)).ok_or_else(|| {
                    format!(
                        "primitive {} has no attribute {name} (a custom scalar attribute, `_` first)",
                        primitive.index()
                    )
                })?;
                let get = |b: gltf::Buffer<'_>| buffers.get(b.index()).map(|d| &d[..]);
                let read = gltf::accessor::Iter::<f32>::new(accessor, get).ok_or_else(|| {
                    format!("{name} of primitive {} is not readable", primitive.index())
                })?;
                let before = out.len();
                out.extend(read.map(f64::from));
                if out.len() - before != n as usize {
                    return Err(format!(
                        "{name} of primitive {} has {} values for {n} vertices",
                        primitive.index(),
                        out.len() - before
                    ));
                }
            }
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..n).collect(),
            };
            self.append(
                positions,
                indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]),
            );
        }
        if self.triangles.is_empty() {
            return Err(format!("mesh {} has no triangle primitive", mesh.index()));
        }
        self.attributes = names.into_iter().zip(values).collect();
        Ok(())
    }

    /// Appends a part's vertices and its triangles (indices local to the part).
    fn append(
        &mut self,
        vertices: impl IntoIterator<Item = [f64; 3]>,
        triangles: impl IntoIterator<Item = [u32; 3]>,
    ) {
        let base = self.vertices.len() as u32;
        self.vertices.extend(vertices);
        self.triangles.extend(
            triangles
                .into_iter()
                .map(|t| t.map(|i| base.saturating_add(i))),
        );
    }
}

/// The world transform of the first node that instantiates mesh `mesh`: the default scene's
/// nodes first, then every scene's.
fn node_transform(gltf: &gltf::Gltf, mesh: usize) -> Option<DMat4> {
    fn find(node: gltf::Node<'_>, parent: DMat4, mesh: usize) -> Option<DMat4> {
        let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        let world = parent * local;
        if node.mesh().is_some_and(|m| m.index() == mesh) {
            return Some(world);
        }
        node.children().find_map(|c| find(c, world, mesh))
    }
    let scenes = gltf.default_scene().into_iter().chain(gltf.scenes());
    scenes
        .flat_map(|s| s.nodes().collect::<Vec<_>>())
        .find_map(|n| find(n, DMat4::IDENTITY, mesh))
}

/// A binary file, refused unless it is a regular file of at most [`super::MAX_FILE_BYTES`].
fn read_bytes(path: &Path) -> Result<Vec<u8>, String> {
    let meta = std::fs::metadata(path).map_err(|e| format!("{}: {e}", path.display()))?;
    if !meta.is_file() {
        return Err(format!("{}: not a regular file", path.display()));
    }
    if meta.len() > super::MAX_FILE_BYTES {
        return Err(format!(
            "{}: larger than {} bytes (MAX_FILE_BYTES)",
            path.display(),
            super::MAX_FILE_BYTES
        ));
    }
    std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))
}
