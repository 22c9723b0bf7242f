//! The viewer's reference-difference debug view: the path-traced reference `valgi eval` cached
//! for the view on screen (`--reference DIR`, [`crate::eval::find_cached_reference`]),
//! uploaded once as two textures that the present pass subtracts from the method's output.
//! A cached reference is a mono image of a scene camera at one time and size, so the view
//! applies only while the window shows exactly that: one view, the scene's camera not flown,
//! the field of view not overridden, the same time and size. Otherwise the image is drawn as
//! usual and the panel says why.

use std::path::{Path, PathBuf};

use crate::eval::{find_cached_reference, CachedMatch};
use crate::gpu::GpuContext;
use crate::image_io::Image;

/// What the difference needs to know of the view on screen.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceView {
    pub scene_key: String,
    pub camera: Option<String>,
    pub size: (u32, u32),
    pub time: f32,
    /// Why the view on screen cannot have a cached reference (flown camera, stereo rig…).
    pub unmatchable: Option<&'static str>,
}

/// A cached reference on the GPU.
struct Loaded {
    found: CachedMatch,
    direct: wgpu::TextureView,
    indirect: wgpu::TextureView,
}

/// The reference textures the present pass binds: the loaded reference, or 1×1 black ones.
pub struct ReferenceOverlay {
    dir: Option<PathBuf>,
    empty: wgpu::TextureView,
    /// The view last looked up and what was found for it.
    looked_up: Option<ReferenceView>,
    loaded: Option<Loaded>,
    /// Why nothing is shown, when nothing is.
    note: String,
}

fn upload(ctx: &GpuContext, label: &str, image: &Image) -> wgpu::TextureView {
    let size = (image.width, image.height);
    let texture = crate::gpu::GpuBytes::default().texture_2d(
        &ctx.device,
        label,
        size,
        wgpu::TextureFormat::Rgba32Float,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    );
    ctx.write_texture_2d(&texture, 0, bytemuck::cast_slice(&image.pixels), size, 16);
    texture.create_view(&Default::default())
}

impl ReferenceOverlay {
    pub fn new(ctx: &GpuContext, dir: Option<&Path>) -> Self {
        let black = Image {
            width: 1,
            height: 1,
            pixels: vec![[0.0; 4]],
        };
        Self {
            dir: dir.map(Path::to_path_buf),
            empty: upload(ctx, "no reference", &black),
            looked_up: None,
            loaded: None,
            note: match dir {
                None => "no --reference folder given".into(),
                Some(_) => String::new(),
            },
        }
    }

    /// Looks the reference up again when the view changed; true when the textures the present
    /// pass must bind changed.
    pub fn update(&mut self, ctx: &GpuContext, view: &ReferenceView) -> bool {
        if self.looked_up.as_ref() == Some(view) {
            return false;
        }
        self.looked_up = Some(view.clone());
        let had = self.loaded.is_some();
        let Some(dir) = &self.dir else {
            return false;
        };
        if let Some(why) = view.unmatchable {
            self.note = why.to_string();
            self.loaded = None;
            return had;
        }
        // The same reference as before: nothing to upload.
        let found = find_cached_reference(
            dir,
            &view.scene_key,
            view.camera.as_deref(),
            view.size,
            view.time,
        );
        if let (Some(f), Some(l)) = (&found, &self.loaded) {
            if *f == l.found {
                return false;
            }
        }
        self.loaded = None;
        let Some(found) = found else {
            self.note = format!(
                "{} holds no reference for scene {} camera {} at {}x{}, t = {} (run valgi eval with that view)",
                dir.display(),
                view.scene_key,
                view.camera.as_deref().unwrap_or("-"),
                view.size.0,
                view.size.1,
                view.time
            );
            return had;
        };
        match (
            Image::read_exr(&found.direct),
            Image::read_exr(&found.indirect),
        ) {
            (Ok(direct), Ok(indirect))
                if (direct.width, direct.height) == view.size
                    && (indirect.width, indirect.height) == view.size =>
            {
                self.note = String::new();
                self.loaded = Some(Loaded {
                    direct: upload(ctx, "reference direct", &direct),
                    indirect: upload(ctx, "reference indirect", &indirect),
                    found,
                });
                true
            }
            (Err(e), _) | (_, Err(e)) => {
                self.note = format!("cached reference unreadable: {e}");
                had
            }
            _ => {
                self.note = format!("{}: its size is not the key's", found.direct.display());
                had
            }
        }
    }

    /// The direct and indirect reference textures to bind (black when none is loaded).
    pub fn textures(&self) -> (&wgpu::TextureView, &wgpu::TextureView) {
        match &self.loaded {
            Some(l) => (&l.direct, &l.indirect),
            None => (&self.empty, &self.empty),
        }
    }

    /// The 1×1 black texture bound where no reference is.
    pub fn empty(&self) -> &wgpu::TextureView {
        &self.empty
    }

    /// The key of the reference on screen.
    pub fn key(&self) -> Option<&str> {
        self.loaded.as_ref().map(|l| l.found.key.as_str())
    }

    /// Why no reference is on screen ("" when one is).
    pub fn note(&self) -> &str {
        &self.note
    }
}
