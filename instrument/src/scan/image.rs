//! A height image: `xres × yres` heights (m), row-major, row `i` at `y = y_offset + (i + ½)·dy`,
//! column `j` at `x = x_offset + (j + ½)·dx` (pixel centres, as Gwyddion places them).

/// A scanned height image.
#[derive(Debug, Clone, PartialEq)]
pub struct HeightImage {
    /// Pixels per row.
    pub xres: usize,
    /// Rows.
    pub yres: usize,
    /// Width of the imaged region (m).
    pub x_real: f64,
    /// Height of the imaged region (m).
    pub y_real: f64,
    /// x of the region's left edge (m).
    pub x_offset: f64,
    /// y of the region's first row's edge (m).
    pub y_offset: f64,
    /// Heights (m), row-major, `yres` rows of `xres`.
    pub data: Vec<f64>,
}

impl HeightImage {
    /// Pixel pitch along x (m).
    pub fn dx(&self) -> f64 {
        self.x_real / self.xres as f64
    }

    /// Pixel pitch along y (m).
    pub fn dy(&self) -> f64 {
        self.y_real / self.yres as f64
    }

    /// x of column `j`'s centre (m).
    pub fn x_at(&self, j: f64) -> f64 {
        self.x_offset + (j + 0.5) * self.dx()
    }

    /// y of row `i`'s centre (m).
    pub fn y_at(&self, i: f64) -> f64 {
        self.y_offset + (i + 0.5) * self.dy()
    }

    /// Fractional column of `x` (m): the inverse of [`HeightImage::x_at`].
    pub fn col_of(&self, x: f64) -> f64 {
        (x - self.x_offset) / self.dx() - 0.5
    }

    /// Fractional row of `y` (m).
    pub fn row_of(&self, y: f64) -> f64 {
        (y - self.y_offset) / self.dy() - 0.5
    }

    /// Height at row `i`, column `j` (m).
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.data[i * self.xres + j]
    }

    /// Bilinear interpolation at fractional `(row, col)`, clamped to the image (m).
    pub fn sample(&self, row: f64, col: f64) -> f64 {
        let r = row.clamp(0.0, (self.yres - 1) as f64);
        let c = col.clamp(0.0, (self.xres - 1) as f64);
        let (i0, j0) = (r.floor() as usize, c.floor() as usize);
        let (i1, j1) = ((i0 + 1).min(self.yres - 1), (j0 + 1).min(self.xres - 1));
        let (fr, fc) = (r - i0 as f64, c - j0 as f64);
        let top = self.at(i0, j0) * (1.0 - fc) + self.at(i0, j1) * fc;
        let bottom = self.at(i1, j0) * (1.0 - fc) + self.at(i1, j1) * fc;
        top * (1.0 - fr) + bottom * fr
    }

    /// Lowest and highest height (m).
    pub fn z_range(&self) -> (f64, f64) {
        self.data
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &z| {
                (lo.min(z), hi.max(z))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coordinates_and_interpolation() {
        let img = HeightImage {
            xres: 4,
            yres: 2,
            x_real: 4.0,
            y_real: 2.0,
            x_offset: 10.0,
            y_offset: 20.0,
            data: vec![0.0, 1.0, 2.0, 3.0, 10.0, 11.0, 12.0, 13.0],
        };
        assert_eq!(img.x_at(0.0), 10.5);
        assert_eq!(img.col_of(img.x_at(2.0)), 2.0);
        assert_eq!(img.row_of(21.5), 1.0);
        assert_eq!(img.sample(0.5, 1.5), 6.5);
        assert_eq!(img.sample(-3.0, 9.0), 3.0);
        assert_eq!(img.z_range(), (0.0, 13.0));
    }
}
