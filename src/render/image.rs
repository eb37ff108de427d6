//! 8-bit sRGB images and their PNG files.
//!
//! Written as 8-bit RGB with an `sRGB` chunk (the pixel values are sRGB-encoded by
//! [`super::tonemap`]). The reader converts any 8-bit-or-less PNG (grey, grey + alpha,
//! palette, RGB, RGBA; 16-bit is stripped to 8) to RGB, dropping alpha; it exists
//! mainly so tests can check what was written.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use super::RenderError;

/// An 8-bit sRGB image: `rgb` holds `width · height` pixels of three bytes, row-major,
/// top row first.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

impl Image {
    /// A black image.
    #[cfg(test)]
    pub(crate) fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            rgb: vec![0; width as usize * height as usize * 3],
        }
    }

    /// Pixel `(x, y)`, `x < width`, `y < height` (panics outside).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) outside image"
        );
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// Checks that the buffer matches the size and the size is not empty.
    ///
    /// # Errors
    /// [`RenderError::InvalidImage`] otherwise.
    pub(crate) fn validate(&self) -> Result<(), RenderError> {
        let expected = self.width as usize * self.height as usize * 3;
        if self.width == 0 || self.height == 0 {
            return Err(RenderError::InvalidImage(format!(
                "empty size {}x{}",
                self.width, self.height
            )));
        }
        if self.rgb.len() != expected {
            return Err(RenderError::InvalidImage(format!(
                "{}x{} needs {expected} bytes, buffer has {}",
                self.width,
                self.height,
                self.rgb.len()
            )));
        }
        Ok(())
    }

    /// Encodes the image as PNG bytes.
    ///
    /// # Errors
    /// [`RenderError::InvalidImage`] for an inconsistent image,
    /// [`RenderError::PngEncode`] (with an empty path) if the encoder fails.
    pub(crate) fn to_png_bytes(&self) -> Result<Vec<u8>, RenderError> {
        self.validate()?;
        let encode_err = |cause| RenderError::PngEncode {
            path: Default::default(),
            cause,
        };
        let mut bytes = Vec::new();
        let mut enc = png::Encoder::new(&mut bytes, self.width, self.height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = enc.write_header().map_err(encode_err)?;
        writer.write_image_data(&self.rgb).map_err(encode_err)?;
        writer.finish().map_err(encode_err)?;
        Ok(bytes)
    }

    /// Writes the image to `path` as an 8-bit RGB PNG (encoded in memory first, so a
    /// failure never leaves a half-written image behind it but the OS error).
    ///
    /// # Errors
    /// [`RenderError::InvalidImage`], [`RenderError::PngEncode`] or
    /// [`RenderError::Io`], naming `path`.
    pub fn write_png(&self, path: &Path) -> Result<(), RenderError> {
        let bytes = self.to_png_bytes().map_err(|e| match e {
            RenderError::PngEncode { cause, .. } => RenderError::PngEncode {
                path: path.to_path_buf(),
                cause,
            },
            other => other,
        })?;
        std::fs::write(path, bytes).map_err(|cause| RenderError::Io {
            path: path.to_path_buf(),
            cause,
        })
    }

    /// Reads a PNG file as 8-bit RGB.
    ///
    /// # Errors
    /// [`RenderError::Io`] when the file cannot be opened, [`RenderError::PngDecode`]
    /// for a malformed PNG, [`RenderError::UnsupportedPng`] for an animated one.
    pub fn read_png(path: &Path) -> Result<Self, RenderError> {
        let file = File::open(path).map_err(|cause| RenderError::Io {
            path: path.to_path_buf(),
            cause,
        })?;
        let decode_err = |cause| RenderError::PngDecode {
            path: path.to_path_buf(),
            cause,
        };
        let mut decoder = png::Decoder::new(BufReader::new(file));
        decoder.set_transformations(png::Transformations::normalize_to_color8());
        let mut reader = decoder.read_info().map_err(decode_err)?;
        if reader.info().animation_control.is_some() {
            return Err(RenderError::UnsupportedPng {
                path: path.to_path_buf(),
                reason: "animated PNG".to_string(),
            });
        }
        let size = reader
            .output_buffer_size()
            .ok_or_else(|| RenderError::UnsupportedPng {
                path: path.to_path_buf(),
                reason: "image too large for memory".to_string(),
            })?;
        let mut buf = vec![0u8; size];
        let info = reader.next_frame(&mut buf).map_err(decode_err)?;
        let (w, h) = (info.width as usize, info.height as usize);
        let channels = match info.color_type {
            png::ColorType::Grayscale => 1,
            png::ColorType::GrayscaleAlpha => 2,
            png::ColorType::Rgb => 3,
            png::ColorType::Rgba => 4,
            png::ColorType::Indexed => {
                return Err(RenderError::UnsupportedPng {
                    path: path.to_path_buf(),
                    reason: "palette not expanded".to_string(),
                })
            }
        };
        let mut rgb = Vec::with_capacity(w * h * 3);
        for row in buf.chunks(info.line_size).take(h) {
            for px in row[..w * channels].chunks_exact(channels) {
                match channels {
                    1 | 2 => rgb.extend_from_slice(&[px[0]; 3]),
                    _ => rgb.extend_from_slice(&px[..3]),
                }
            }
        }
        let image = Self {
            width: info.width,
            height: info.height,
            rgb,
        };
        image.validate().map_err(|e| RenderError::UnsupportedPng {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        Ok(image)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.png");
        let mut img = Image::new(5, 3);
        for (k, b) in img.rgb.iter_mut().enumerate() {
            *b = (k * 17 % 256) as u8;
        }
        img.write_png(&path).unwrap();
        assert_eq!(Image::read_png(&path).unwrap(), img);
    }

    #[test]
    fn errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.png");
        let e = Image::read_png(&missing).unwrap_err().to_string();
        assert!(e.contains("missing.png"), "{e}");
        let junk = dir.path().join("junk.png");
        std::fs::write(&junk, b"not a png").unwrap();
        let e = Image::read_png(&junk).unwrap_err().to_string();
        assert!(e.contains("junk.png") && e.contains("PNG decoding"), "{e}");
        let bad = Image {
            width: 2,
            height: 2,
            rgb: vec![0; 5],
        };
        assert!(matches!(
            bad.write_png(&dir.path().join("x.png")),
            Err(RenderError::InvalidImage(_))
        ));
    }
}
