//! Bounded, contained reading of scene files and the files they reference.
//!
//! A scene file is untrusted input: its references (glTF buffer and image URIs, OBJ `mtllib`
//! and `map_Kd`, Mitsuba `filename`s) must not make the renderer read device files, follow
//! `..` out of the scene's folder, or allocate memory for sizes the file merely declares. Every
//! reader goes through these functions, so the rules live in one place:
//!
//! - a referenced file is a regular file inside the referring file's folder (after resolving
//!   symbolic links), unless [`ReadPolicy::allow_external_paths`] is set, which admits absolute
//!   paths and paths outside the folder, but still only regular files;
//! - no file larger than [`MAX_FILE_BYTES`] is read, and reads stop at that size even when the
//!   file grows while being read;
//! - decoded images are limited to [`MAX_IMAGE_SIDE`] texels a side and [`MAX_IMAGE_BYTES`] of
//!   decoder memory, checked from the image header before the pixels are decoded.

use std::io::Read;
use std::path::{Component, Path, PathBuf};

/// Largest scene, buffer, mesh or image file read, bytes.
pub const MAX_FILE_BYTES: u64 = 2 << 30;
/// Largest texture side accepted, texels (GPUs commonly cap 2D textures at 16384).
pub const MAX_IMAGE_SIDE: u32 = 16384;
/// Most memory an image decoder may allocate, bytes.
pub const MAX_IMAGE_BYTES: u64 = 1 << 30;

/// What references in a scene file may point at.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadPolicy {
    /// Admit absolute paths and paths outside the scene file's folder.
    pub allow_external_paths: bool,
}

/// Reads a whole file that must be a regular file of at most [`MAX_FILE_BYTES`]. The error is
/// the problem alone; callers prefix the file name.
pub fn read_regular_file(path: &Path) -> Result<Vec<u8>, String> {
    let metadata = std::fs::metadata(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            "file not found".to_string()
        } else {
            format!("cannot read file: {e}")
        }
    })?;
    if !metadata.is_file() {
        return Err("not a regular file".into());
    }
    if metadata.len() > MAX_FILE_BYTES {
        return Err(format!(
            "file has {} bytes, more than the {MAX_FILE_BYTES}-byte limit",
            metadata.len()
        ));
    }
    let file = std::fs::File::open(path).map_err(|e| format!("cannot read file: {e}"))?;
    let mut bytes = Vec::with_capacity(metadata.len() as usize);
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read file: {e}"))?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(format!(
            "file grew past the {MAX_FILE_BYTES}-byte limit while being read"
        ));
    }
    Ok(bytes)
}

/// A scene file read for a reader: its bytes, the folder its references resolve against, and
/// its name for messages.
pub struct SceneFile {
    pub bytes: Vec<u8>,
    pub base_dir: PathBuf,
    pub display: String,
}

/// Reads the scene file at `path` with [`read_regular_file`]; `error` builds the reader's
/// error from the file's display name and the problem.
pub fn read_scene_file(
    path: &Path,
    error: impl FnOnce(String, String) -> crate::scene::SceneError,
) -> Result<SceneFile, crate::scene::SceneError> {
    let display = path.display().to_string();
    match read_regular_file(path) {
        Ok(bytes) => Ok(SceneFile {
            bytes,
            base_dir: path.parent().map(Path::to_path_buf).unwrap_or_default(),
            display,
        }),
        Err(message) => Err(error(display, message)),
    }
}

/// The [`read_scene_file`] error of readers that report [`crate::scene::SceneError::Other`].
pub fn other_error(path: String, message: String) -> crate::scene::SceneError {
    crate::scene::SceneError::Other { path, message }
}

/// Resolves `reference` (a relative path as written in the scene file, already
/// percent-decoded) against `base_dir`, the referring file's folder, under `policy`. Returns the
/// canonical path of an existing regular file. `kind` names the reference in errors ("buffer",
/// "image", "mesh").
pub fn resolve_reference(
    base_dir: &Path,
    reference: &str,
    kind: &str,
    policy: ReadPolicy,
) -> Result<PathBuf, String> {
    resolve_reference_within(base_dir, base_dir, reference, kind, policy)
}

/// [`resolve_reference`] for a reference written in a file of a sub-folder of the scene (a
/// Mitsuba include): `reference` is relative to `base_dir`, and must stay inside
/// `scene_dir`, the scene file's folder.
pub fn resolve_reference_within(
    base_dir: &Path,
    scene_dir: &Path,
    reference: &str,
    kind: &str,
    policy: ReadPolicy,
) -> Result<PathBuf, String> {
    if reference.is_empty() {
        return Err(format!("{kind} reference is an empty path"));
    }
    if reference.contains('\0') {
        return Err(format!("{kind} path '{reference}' contains a NUL byte"));
    }
    let relative = Path::new(reference);
    let absolute =
        relative.has_root() || matches!(relative.components().next(), Some(Component::Prefix(_)));
    if absolute && !policy.allow_external_paths {
        return Err(format!(
            "{kind} path '{reference}' is absolute; only files inside the scene's folder are \
             read unless external paths are allowed (--allow-external-paths)"
        ));
    }
    let joined = base_dir.join(relative);
    let canonical = std::fs::canonicalize(&joined).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            format!(
                "missing {kind} file '{reference}' (looked for {})",
                joined.display()
            )
        } else {
            format!("cannot resolve {kind} file '{}': {e}", joined.display())
        }
    })?;
    if !policy.allow_external_paths {
        let folder = std::fs::canonicalize(if scene_dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            scene_dir
        })
        .map_err(|e| {
            format!(
                "cannot resolve the scene folder {}: {e}",
                scene_dir.display()
            )
        })?;
        if !canonical.starts_with(&folder) {
            return Err(format!(
                "{kind} path '{reference}' leads outside the scene's folder (to {}); only files \
                 inside it are read unless external paths are allowed (--allow-external-paths)",
                canonical.display()
            ));
        }
    }
    let metadata = std::fs::metadata(&canonical)
        .map_err(|e| format!("cannot read {kind} file '{}': {e}", canonical.display()))?;
    if !metadata.is_file() {
        return Err(format!(
            "{kind} path '{reference}' is not a regular file ({})",
            canonical.display()
        ));
    }
    Ok(canonical)
}

/// [`resolve_reference`] then [`read_regular_file`].
pub fn read_reference(
    base_dir: &Path,
    reference: &str,
    kind: &str,
    policy: ReadPolicy,
) -> Result<Vec<u8>, String> {
    let path = resolve_reference(base_dir, reference, kind, policy)?;
    read_regular_file(&path).map_err(|m| format!("{kind} file '{}': {m}", path.display()))
}

/// Decodes an encoded PNG or JPEG to RGBA8 within the image limits, which are checked against
/// the dimensions in the image header before any pixel is decoded.
pub fn decode_rgba8(encoded: &[u8]) -> Result<image::RgbaImage, String> {
    let mut reader = image::ImageReader::new(std::io::Cursor::new(encoded))
        .with_guessed_format()
        .map_err(|e| format!("cannot read the image header: {e}"))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    limits.max_alloc = Some(MAX_IMAGE_BYTES);
    reader.limits(limits);
    let decoded = reader.decode().map_err(|e| match e {
        image::ImageError::Limits(l) => format!(
            "image exceeds the decoder limits ({l}; at most {MAX_IMAGE_SIDE}² texels and \
             {MAX_IMAGE_BYTES} bytes)"
        ),
        other => other.to_string(),
    })?;
    Ok(decoded.to_rgba8())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folder(name: &str) -> PathBuf {
        let dir = std::env::temp_dir()
            .join(format!("valgi-files-{}", std::process::id()))
            .join(name);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn references_stay_inside_the_folder() {
        let root = folder("contain");
        let inner = root.join("scene");
        std::fs::create_dir_all(inner.join("sub")).unwrap();
        std::fs::write(inner.join("sub/a.bin"), b"abc").unwrap();
        std::fs::write(root.join("outside.bin"), b"xyz").unwrap();
        let strict = ReadPolicy::default();
        let open = ReadPolicy {
            allow_external_paths: true,
        };
        assert_eq!(
            read_reference(&inner, "sub/a.bin", "buffer", strict).unwrap(),
            b"abc"
        );
        // `..` that stays inside is fine; one that leaves is not, unless allowed.
        assert!(read_reference(&inner, "sub/../sub/a.bin", "buffer", strict).is_ok());
        let err = read_reference(&inner, "../outside.bin", "buffer", strict).unwrap_err();
        assert!(err.contains("outside the scene's folder"), "{err}");
        assert_eq!(
            read_reference(&inner, "../outside.bin", "buffer", open).unwrap(),
            b"xyz"
        );
        let absolute = root.join("outside.bin");
        let err = read_reference(&inner, absolute.to_str().unwrap(), "image", strict).unwrap_err();
        assert!(err.contains("absolute") && err.contains("image"), "{err}");
        assert!(read_reference(&inner, absolute.to_str().unwrap(), "image", open).is_ok());
        // Device files are never read, allowed or not.
        for device in ["/dev/zero", "/dev/urandom"] {
            if Path::new(device).exists() {
                let err = read_reference(&inner, device, "buffer", open).unwrap_err();
                assert!(err.contains("not a regular file"), "{err}");
            }
        }
        assert!(read_reference(&inner, "sub", "buffer", strict)
            .unwrap_err()
            .contains("not a regular file"));
        assert!(read_reference(&inner, "nope.bin", "buffer", strict)
            .unwrap_err()
            .contains("missing buffer file"));
        assert!(read_reference(&inner, "", "buffer", strict).is_err());
    }

    #[cfg(unix)]
    #[test]
    fn symbolic_links_out_of_the_folder_are_refused() {
        let root = folder("links");
        let inner = root.join("scene");
        std::fs::create_dir_all(&inner).unwrap();
        std::fs::write(root.join("secret"), b"s").unwrap();
        let link = inner.join("link.bin");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(root.join("secret"), &link).unwrap();
        let err = read_reference(&inner, "link.bin", "buffer", ReadPolicy::default()).unwrap_err();
        assert!(err.contains("outside"), "{err}");
        let dev = inner.join("zero.bin");
        let _ = std::fs::remove_file(&dev);
        std::os::unix::fs::symlink("/dev/zero", &dev).unwrap();
        let err = read_reference(
            &inner,
            "zero.bin",
            "buffer",
            ReadPolicy {
                allow_external_paths: true,
            },
        )
        .unwrap_err();
        assert!(err.contains("not a regular file"), "{err}");
    }

    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in bytes {
            crc ^= b as u32;
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    #[test]
    fn oversized_image_headers_fail_before_decoding() {
        // A PNG header declaring 100000 × 100000 texels with no pixel data.
        let mut png = b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR".to_vec();
        png.extend(100_000u32.to_be_bytes());
        png.extend(100_000u32.to_be_bytes());
        png.extend([8, 6, 0, 0, 0]);
        let crc = crc32(&png[12..]);
        png.extend(crc.to_be_bytes());
        let err = decode_rgba8(&png).unwrap_err();
        assert!(err.contains("limit"), "{err}");
    }
}
