//! AFM tapping-mode scans: tip shape, tip dilation, the raster, GSF/PNG output, localization.

mod dilation;
mod gsf;
mod image;
mod localize;
mod preview;
mod raster;
mod surface;
mod tip;

#[cfg(test)]
mod tests;

pub use dilation::{grid_dilation, image_height, sphere_image, substrate_image, tip_map};
pub use gsf::{GsfError, GsfFile, header as gsf_header, read_gsf, write_gsf};
pub use image::HeightImage;
pub use localize::{LocateError, Located, find_particles, levelled, localize};
pub use preview::{viridis, write_png};
pub use raster::{ScanLine, ScanParams, Scanner, scan};
pub use surface::{Sphere, Surface};
pub use tip::Tip;
