//! Writing frames: HDR OpenEXR (R, G, B radiance and A = the volume's transparency, 32-bit
//! float) and a tone-mapped sRGB PNG. Both are encoded in memory and written atomically, so a
//! failure leaves no half-written file.

use std::io::Cursor;
use std::path::Path;

use exr::prelude::{
    AnyChannel, AnyChannels, Blocks, Compression, Encoding, FlatSamples, Layer, LayerAttributes,
    LineOrder, SmallVec, Vec2, WritableImage,
};

/// A rendered frame: linear radiance per pixel (rows top to bottom) and the volume's
/// transparency (green channel) per pixel.
#[derive(Debug, Clone)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Linear R, G, B radiance per pixel, row-major (1/sr per unit solar irradiance).
    pub rgb: Vec<[f32; 3]>,
    /// The volume's transparency T_vol (green channel) per pixel, 0…1.
    pub transparency: Vec<f32>,
}

impl Image {
    /// An image from (rgb, T_vol) per pixel, row-major.
    pub fn from_pixels(width: usize, height: usize, pixels: &[([f32; 3], f32)]) -> Self {
        Self {
            width,
            height,
            rgb: pixels.iter().map(|p| p.0).collect(),
            transparency: pixels.iter().map(|p| p.1).collect(),
        }
    }
}

/// Why a frame could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The EXR or PNG encoder failed; nothing was written.
    #[error("{path}: encoding failed: {message}")]
    Encode {
        /// The file that was to be written.
        path: String,
        /// The encoder's error.
        message: String,
    },
    /// The target cannot be written (not a regular file, or the write failed); it is left
    /// untouched.
    #[error(transparent)]
    Output(#[from] format::OutputError),
}

/// The sRGB transfer curve (IEC 61966-2-1) of a linear value in [0, 1].
pub fn srgb_encode(linear: f64) -> f64 {
    if linear <= 0.003_130_8 {
        12.92 * linear
    } else {
        1.055 * linear.powf(1.0 / 2.4) - 0.055
    }
}

fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    Ok(format::write_output(path, bytes, &[])?)
}

impl Image {
    /// Writes R, G, B (linear radiance per unit solar irradiance, 1/sr) and A (transparency).
    pub fn write_exr(&self, path: &Path) -> Result<(), WriteError> {
        self.write_exr_with(path, Vec::new())
    }

    /// [`Image::write_exr`] with further 32-bit float channels `(name, one value per pixel)`,
    /// such as the path tracer's `stderr.R`, `stderr.G`, `stderr.B`.
    pub fn write_exr_with(
        &self,
        path: &Path,
        extra: Vec<(String, Vec<f32>)>,
    ) -> Result<(), WriteError> {
        let channel = |name: &str, values: Vec<f32>| {
            let mut c = AnyChannel::new(name, FlatSamples::F32(values));
            c.quantize_linearly = false;
            c
        };
        let plane = |c: usize| self.rgb.iter().map(|p| p[c]).collect::<Vec<f32>>();
        let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
        for (name, values) in [
            ("R", plane(0)),
            ("G", plane(1)),
            ("B", plane(2)),
            ("A", self.transparency.clone()),
        ] {
            list.push(channel(name, values));
        }
        for (name, values) in extra {
            if values.len() != self.width * self.height {
                return Err(WriteError::Encode {
                    path: path.display().to_string(),
                    message: format!("channel {name} has {} values", values.len()),
                });
            }
            list.push(channel(&name, values));
        }
        let channels = AnyChannels::sort(list);
        let layer = Layer::new(
            Vec2(self.width, self.height),
            LayerAttributes::named("photometeor render"),
            Encoding {
                compression: Compression::ZIP16,
                blocks: Blocks::ScanLines,
                line_order: LineOrder::Increasing,
            },
            channels,
        );
        let mut bytes = Vec::new();
        exr::prelude::Image::from_layer(layer)
            .write()
            .non_parallel()
            .to_buffered(Cursor::new(&mut bytes))
            .map_err(|e| WriteError::Encode {
                path: path.display().to_string(),
                message: e.to_string(),
            })?;
        write_bytes(path, &bytes)
    }

    /// Luminance (Rec. 709 weights) of each pixel.
    pub fn luminance(&self) -> Vec<f64> {
        self.rgb
            .iter()
            .map(|p| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64)
            .collect()
    }

    /// The exposure [`Image::write_png`] uses when none is given: the 97th percentile of
    /// luminance maps to 1 − e^{−1.5} ≈ 0.78 before the sRGB curve.
    pub fn auto_exposure(&self) -> f64 {
        let mut lum = self.luminance();
        lum.sort_by(f64::total_cmp);
        let p = lum[((lum.len() - 1) as f64 * 0.97) as usize];
        if p > 0.0 { 1.5 / p } else { 1.0 }
    }

    /// 8-bit sRGB: v = 1 − e^{−exposure·L} per channel, then the sRGB transfer curve.
    pub fn to_srgb8(&self, exposure: f64) -> Vec<u8> {
        let encode = |l: f32| {
            let v = 1.0 - (-(exposure * l.max(0.0) as f64)).exp();
            (srgb_encode(v) * 255.0).round().clamp(0.0, 255.0) as u8
        };
        self.rgb.iter().flat_map(|p| p.map(encode)).collect()
    }

    /// Writes an 8-bit sRGB PNG of [`Image::to_srgb8`] at `exposure`.
    pub fn write_png(&self, path: &Path, exposure: f64) -> Result<(), WriteError> {
        write_png_rgb8(path, self.width, self.height, &self.to_srgb8(exposure))
    }
}

/// Writes 8-bit sRGB pixels (R, G, B per pixel, rows top to bottom) as a PNG, atomically.
pub fn write_png_rgb8(
    path: &Path,
    width: usize,
    height: usize,
    data: &[u8],
) -> Result<(), WriteError> {
    let mut bytes = Vec::new();
    let encode_err = |e: png::EncodingError| WriteError::Encode {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    {
        let mut encoder = png::Encoder::new(&mut bytes, width as u32, height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = encoder.write_header().map_err(encode_err)?;
        writer.write_image_data(data).map_err(encode_err)?;
    }
    write_bytes(path, &bytes)
}
