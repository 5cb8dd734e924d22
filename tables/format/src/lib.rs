//! The file format of a photometeor bake: what a renderer reads, and nothing that computes it.
//!
//! A bake directory holds `manifest.json` ([`manifest`]: the grid, the channel definitions and
//! one [`FieldEntry`] per particle field) and one OpenEXR file per field ([`exr`]: rows
//! Ams_1..Ams_N × columns θ_k = k·Δθ, channels R, G, B in 1/sr, F_1..F_N in the header), and
//! beside it the field's single-scattering optics per wavelength ([`single`]) and its Poisson
//! mixtures of all scattering orders ([`poisson`]) and Biri et al.'s point-light kernel
//! ([`biri`]): three side tables of one layout, written and read by one codec ([`side`]).
//! Writers go through [`write_file_atomically`] (a command's user-named outputs through
//! [`write_output`], which refuses devices, FIFOs, directories and the files it reads);
//! readers through [`read_regular_file`], so a FIFO or a device is never read and no file is
//! read past a size bound. Every reader checks
//! what it reads against the contract, naming the file and the failed check.
//!
//! This crate depends on neither the solver nor the bake: an engine that loads tables links
//! only this and `photometeor-runtime`.

#![warn(missing_docs)]

pub mod atomic;
pub mod biri;
pub mod commit;
pub mod export;
pub mod exr;
pub mod manifest;
pub mod output;
pub mod poisson;
pub mod sections;
pub mod side;
pub mod single;

pub use atomic::{read_regular_file, write_file_atomically};
pub use biri::{BiriTable, biri_exr_bytes, biri_file_name, decode_biri_exr};
pub use commit::{
    BakeLock, CommitError, Staging, check_no_pending_commit, crc32_hex, roll_forward,
};
pub use exr::{ContractError, FieldImage, IoError, RGB_CHANNELS, read_field_exr, write_field_exr};
pub use manifest::{
    BakeDir, FieldEntry, FieldFiles, MANIFEST_FILE, Manifest, ManifestCheck, ManifestError,
    PerChannel, SweepEntry, parse_manifest, read_manifest, write_manifest,
};
pub use output::{OutputError, check_output, check_output_dir, write_output};
pub use poisson::{PoissonTable, decode_poisson_exr, poisson_exr_bytes, poisson_file_name};
pub use sections::{
    ChannelValues, Channels, FieldKind, Material, Microphysics, QualityRecord, SpectralSampling,
};
pub use single::{SingleScatter, decode_single_exr, single_exr_bytes, single_file_name};
