//! Offscreen drawing read back to the CPU, and the images it gives.

use std::path::Path;

use super::*;
use crate::error::GpuError;
use crate::gpu::GpuContext;

/// RGBA8 pixels, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Four bytes per pixel (R, G, B, A), row by row from the top left.
    pub rgba: Vec<u8>,
}

impl Image {
    /// The RGBA of pixel `(x, y)`, `x` from the left and `y` from the top.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = 4 * (y as usize * self.width as usize + x as usize);
        [
            self.rgba[i],
            self.rgba[i + 1],
            self.rgba[i + 2],
            self.rgba[i + 3],
        ]
    }

    /// Pixels of the plain cloth colour family (red well above blue: no sky, floor or body
    /// colour is), whatever the shading.
    pub fn cloth_pixels(&self) -> usize {
        self.rgba
            .chunks_exact(4)
            .filter(|p| p[0] as i32 - p[2] as i32 > 60 && p[0] as i32 > p[1] as i32 + 20)
            .count()
    }

    /// Distinct colours (a blank picture has one or two).
    pub fn distinct_colours(&self) -> usize {
        let mut seen: Vec<u32> = self
            .rgba
            .chunks_exact(4)
            .map(|p| u32::from_le_bytes([p[0], p[1], p[2], p[3]]))
            .collect();
        seen.sort_unstable();
        seen.dedup();
        seen.len()
    }

    /// `frames` tiled `columns` wide (all the same size), through a [`Sheet`].
    pub fn sheet(frames: &[Image], columns: u32) -> Result<Image, SheetError> {
        let first = frames.first().ok_or(SheetError::Empty)?;
        let count = u32::try_from(frames.len()).unwrap_or(u32::MAX);
        let mut sheet = Sheet::new((first.width, first.height), count, columns)?;
        for (k, f) in frames.iter().enumerate() {
            sheet.place(k as u32, f)?;
        }
        Ok(sheet.finish())
    }

    /// Writes the image to `path` as an 8-bit RGBA PNG; an error names the path.
    pub fn write_png(&self, path: &Path) -> Result<(), ImageError> {
        let at = |e: png::EncodingError| ImageError {
            path: path.to_path_buf(),
            source: e,
        };
        let file = std::fs::File::create(path).map_err(|e| at(e.into()))?;
        let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), self.width, self.height);
        encoder.set_color(png::ColorType::Rgba);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(at)?;
        writer.write_image_data(&self.rgba).map_err(at)
    }
}

/// The longest side of a contact sheet, in pixels: a texture size viewers and GPUs take, and at
/// most 1 GiB of RGBA.
pub const MAX_SHEET_SIDE: u32 = 16_384;

/// A contact sheet, filled as each picture arrives (so the pictures need not be held).
pub struct Sheet {
    image: Image,
    tile: (u32, u32),
    columns: u32,
    count: u32,
}

impl Sheet {
    /// A white sheet for `count` pictures of `tile` pixels, `columns` wide (clamped to 1 ..=
    /// `count`); refused past [`MAX_SHEET_SIDE`] a side, before anything is allocated.
    pub fn new(tile: (u32, u32), count: u32, columns: u32) -> Result<Sheet, SheetError> {
        if count == 0 || tile.0 == 0 || tile.1 == 0 {
            return Err(SheetError::Empty);
        }
        let columns = columns.clamp(1, count);
        let rows = count.div_ceil(columns);
        let (w, h) = (
            u64::from(tile.0) * u64::from(columns),
            u64::from(tile.1) * u64::from(rows),
        );
        let max = u64::from(MAX_SHEET_SIDE);
        if w > max || h > max {
            return Err(SheetError::TooLarge {
                width: w,
                height: h,
            });
        }
        Ok(Sheet {
            // Both sides ≤ 2¹⁴: the size fits in u32 and usize.
            image: Image {
                width: w as u32,
                height: h as u32,
                rgba: vec![255; (w * h * 4) as usize],
            },
            tile,
            columns,
            count,
        })
    }

    /// Copies picture `k` (from 0, row by row) into its tile.
    pub fn place(&mut self, k: u32, picture: &Image) -> Result<(), SheetError> {
        let (w, h) = self.tile;
        if (picture.width, picture.height) != (w, h) || k >= self.count {
            return Err(SheetError::Mismatch {
                index: k,
                size: (picture.width, picture.height),
                tile: self.tile,
                count: self.count,
            });
        }
        let (w, h) = (w as usize, h as usize);
        let (cx, cy) = ((k % self.columns) as usize, (k / self.columns) as usize);
        let stride = self.image.width as usize * 4;
        for y in 0..h {
            let src = &picture.rgba[y * w * 4..(y + 1) * w * 4];
            let at = (cy * h + y) * stride + cx * w * 4;
            self.image.rgba[at..at + src.len()].copy_from_slice(src);
        }
        Ok(())
    }

    /// The sheet; tiles never placed stay white.
    pub fn finish(self) -> Image {
        self.image
    }
}

/// A contact sheet that cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum SheetError {
    /// No pictures, or pictures of no pixels.
    #[error("a contact sheet needs at least one picture of at least one pixel")]
    Empty,
    /// Past [`MAX_SHEET_SIDE`] a side.
    #[error(
        "the contact sheet would be {width}x{height} pixels, past {MAX_SHEET_SIDE} a side \
         (1 GiB of RGBA)"
    )]
    TooLarge {
        /// Its width in pixels.
        width: u64,
        /// Its height in pixels.
        height: u64,
    },
    /// A picture of another size than the tiles, or past the last tile.
    #[error(
        "picture {index} is {}x{} for a sheet of {count} tiles of {}x{}",
        size.0, size.1, tile.0, tile.1
    )]
    Mismatch {
        /// The picture's index.
        index: u32,
        /// Its size.
        size: (u32, u32),
        /// The tiles' size.
        tile: (u32, u32),
        /// The tiles on the sheet.
        count: u32,
    },
}

/// An image could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct ImageError {
    /// The file that could not be written.
    pub path: std::path::PathBuf,
    /// Why: the file could not be created, or the PNG encoder failed.
    #[source]
    pub source: png::EncodingError,
}

/// A renderer with its own target texture, read back to the CPU after each draw.
pub struct Offscreen {
    renderer: Renderer,
    size: (u32, u32),
    target: wgpu::Texture,
    view: wgpu::TextureView,
    staging: wgpu::Buffer,
    row: u32,
}

impl Offscreen {
    /// Renders of `width` × `height` on the shared GPU context (software adapters allowed).
    pub fn new(width: u32, height: u32) -> Result<Self, GpuError> {
        let limit = 8192;
        if width == 0 || height == 0 || width > limit || height > limit {
            return Err(GpuError::Device {
                adapter: "offscreen".into(),
                what: format!("image size {width}x{height} is outside 1..={limit} per side"),
            });
        }
        let ctx = GpuContext::shared(true)?;
        let renderer = Renderer::new(ctx.clone(), FORMAT)?;
        let target = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("offscreen"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = target.create_view(&Default::default());
        let row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("offscreen read-back"),
            size: row as u64 * height as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Self {
            renderer,
            size: (width, height),
            target,
            view,
            staging,
            row,
        })
    }

    /// The renderer that draws into its texture.
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// Draws `sim` as it stands and reads the picture back.
    pub fn capture(
        &mut self,
        sim: &mut Simulation,
        camera: &Camera,
        style: &Style,
    ) -> Result<Image, GpuError> {
        let size = self.size;
        self.renderer
            .draw(sim, 1.0, None, camera, style, &self.view, size)?;
        let (width, height) = size;
        let row = self.row;
        let mut rgba = vec![0u8; (width * height * 4) as usize];
        let ctx = self.renderer.ctx.clone();
        crate::gpu::read_staging(
            &ctx,
            "offscreen read-back",
            &self.staging,
            row as u64 * height as u64,
            |encoder| {
                encoder.copy_texture_to_buffer(
                    wgpu::TexelCopyTextureInfo {
                        texture: &self.target,
                        mip_level: 0,
                        origin: wgpu::Origin3d::ZERO,
                        aspect: wgpu::TextureAspect::All,
                    },
                    wgpu::TexelCopyBufferInfo {
                        buffer: &self.staging,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset: 0,
                            bytes_per_row: Some(row),
                            rows_per_image: Some(height),
                        },
                    },
                    wgpu::Extent3d {
                        width,
                        height,
                        depth_or_array_layers: 1,
                    },
                );
            },
            |bytes| {
                for y in 0..height as usize {
                    let src = &bytes[y * row as usize..][..width as usize * 4];
                    rgba[y * width as usize * 4..][..width as usize * 4].copy_from_slice(src);
                }
            },
        )?;
        Ok(Image {
            width,
            height,
            rgba,
        })
    }
}
