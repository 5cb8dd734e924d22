//! The R, G, B and A planes of an EXR `photometeor render` (or `view --screenshot`) wrote, read
//! with the `exr` crate: shared by the CLI tests that look at frames.

use std::path::Path;

/// R, G, B, A planes of an EXR written by `photometeor render`, read with the `exr` crate.
pub fn read_rgba(path: &Path) -> (usize, usize, [Vec<f32>; 4]) {
    use exr::prelude::*;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .unwrap();
    let size = image.layer_data.size;
    let plane = |name: &str| -> Vec<f32> {
        let c = image
            .layer_data
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == name)
            .unwrap_or_else(|| panic!("channel {name}"));
        c.sample_data.values_as_f32().collect()
    };
    (
        size.0,
        size.1,
        [plane("R"), plane("G"), plane("B"), plane("A")],
    )
}
