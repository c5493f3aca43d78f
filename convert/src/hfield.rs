//! Heightfields: a grid of ground heights, as MuJoCo's `<hfield>` holds them.
//!
//! One type for every heightfield twin builds: a scenario's terrain (`twin_core::terrain`:
//! rough ground, slopes) and a Gazebo world's `<heightmap>` (a grayscale PNG read by
//! [`Heightfield::from_png`]). Heights are in metres in MuJoCo's layout; [`Heightfield::hfield_element`]
//! and [`Heightfield::placement`] write them as an `<hfield>` asset and the placement of its
//! `hfield` geom (normalized elevations over the lowest height, the geom at that height), and
//! [`Heightfield::height_at`] is the surface MuJoCo collides with.

use std::path::Path;

/// A grid of heights, centred at `center_m`, turned by `yaw_rad` about z.
#[derive(Debug, Clone, PartialEq)]
pub struct Heightfield {
    /// Centre of the grid, world x y, m.
    pub center_m: [f64; 2],
    /// Half extent along the grid's x and y, m.
    pub half_m: [f64; 2],
    /// Rotation about z, radians.
    pub yaw_rad: f64,
    /// Rows (along y).
    pub nrow: usize,
    /// Columns (along x).
    pub ncol: usize,
    /// World heights, m, row-major: row `i` at y = −half_y + i·2·half_y/(nrow−1),
    /// column `j` at x = −half_x + j·2·half_x/(ncol−1) (MuJoCo's layout).
    pub heights_m: Vec<f64>,
}

/// A float for MJCF (shortest round-trip form).
fn num(v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    format!("{v}")
}

impl Heightfield {
    /// Lowest and highest height, m.
    pub fn range_m(&self) -> (f64, f64) {
        self.heights_m.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &h| (lo.min(h), hi.max(h)))
    }

    /// Height of the grid's surface at world (x, y) as MuJoCo triangulates it (each cell split
    /// along its diagonal from (i, j) to (i+1, j+1)); `None` outside the grid.
    pub fn height_at(&self, x: f64, y: f64) -> Option<f64> {
        let (c, s) = (self.yaw_rad.cos(), self.yaw_rad.sin());
        let (dx, dy) = (x - self.center_m[0], y - self.center_m[1]);
        let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
        let [hx, hy] = self.half_m;
        if u.abs() > hx || v.abs() > hy {
            return None;
        }
        let fx = (u + hx) / (2.0 * hx) * (self.ncol - 1) as f64;
        let fy = (v + hy) / (2.0 * hy) * (self.nrow - 1) as f64;
        let j = (fx.floor() as usize).min(self.ncol - 2);
        let i = (fy.floor() as usize).min(self.nrow - 2);
        let (tx, ty) = (fx - j as f64, fy - i as f64);
        let h = |i: usize, j: usize| self.heights_m[i * self.ncol + j];
        let (h00, h01, h10, h11) = (h(i, j), h(i, j + 1), h(i + 1, j), h(i + 1, j + 1));
        Some(if tx >= ty {
            h00 + tx * (h01 - h00) + ty * (h11 - h01)
        } else {
            h00 + ty * (h10 - h00) + tx * (h11 - h10)
        })
    }

    /// The highest surface under a rectangle of half sizes `half_m` (world x, y) centred at
    /// world (x, y), sampled every 1 cm and at the corners; `None` when no sample is over the grid.
    pub fn highest_under(&self, x: f64, y: f64, half_m: [f64; 2]) -> Option<f64> {
        let n = |h: f64| ((2.0 * h / 0.01).ceil() as usize).max(1);
        let (nx, ny) = (n(half_m[0]), n(half_m[1]));
        let mut z: Option<f64> = None;
        for i in 0..=nx {
            for j in 0..=ny {
                let px = x - half_m[0] + 2.0 * half_m[0] * i as f64 / nx as f64;
                let py = y - half_m[1] + 2.0 * half_m[1] * j as f64 / ny as f64;
                if let Some(h) = self.height_at(px, py) {
                    z = Some(z.map_or(h, |z| z.max(h)));
                }
            }
        }
        z
    }

    /// The `<hfield>` asset element named `name`: the heights normalized over the lowest, the
    /// range as its elevation size, 5 cm of base below.
    pub fn hfield_element(&self, name: &str) -> String {
        let (lo, hi) = self.range_m();
        let range = hi - lo;
        let mut x = format!(
            "<hfield name=\"{name}\" nrow=\"{}\" ncol=\"{}\" size=\"{} {} {} 0.05\" elevation=\"",
            self.nrow,
            self.ncol,
            num(self.half_m[0]),
            num(self.half_m[1]),
            num(if range > 0.0 { range } else { 1e-6 })
        );
        // MJCF's `elevation` lists rows from +y down, as an image does (MuJoCo flips them
        // into its row 0 at −y); `heights_m` is in MuJoCo's order.
        for (k, row) in self.heights_m.chunks(self.ncol).rev().enumerate() {
            for (j, v) in row.iter().enumerate() {
                if k > 0 || j > 0 {
                    x.push(' ');
                }
                x.push_str(&num(if range > 0.0 { (v - lo) / range } else { 0.0 }));
            }
        }
        x.push_str("\"/>");
        x
    }

    /// `pos` and `quat` attributes of the heightfield's geom: at the grid's centre and lowest
    /// height, turned by its yaw.
    pub fn placement(&self) -> String {
        let (lo, _) = self.range_m();
        format!(
            "pos=\"{} {} {}\" quat=\"{} 0 0 {}\"",
            num(self.center_m[0]),
            num(self.center_m[1]),
            num(lo),
            num((self.yaw_rad / 2.0).cos()),
            num((self.yaw_rad / 2.0).sin())
        )
    }

    /// A Gazebo `<heightmap>`: the grayscale PNG at `path` (8 or 16 bits; RGB only with equal
    /// channels), `size_m` its extent (x, y) and height range (z), `center_m` the world position
    /// of its centre and of black (z). Pixel (row r, column c) of a W×H image is the height at
    /// x = −size_x/2 + c·size_x/(W−1), y = +size_y/2 − r·size_y/(H−1) (the image's top row at +y,
    /// as Gazebo and MuJoCo read it): `center_z + value/max·size_z`.
    ///
    /// # Errors
    /// What is wrong, naming the PNG, when it can't be read, is not a PNG, is smaller than 2×2
    /// or has colour (the caller names the world element that points at it).
    pub fn from_png(
        path: &Path,
        size_m: [f64; 3],
        center_m: [f64; 3],
        yaw_rad: f64,
    ) -> std::result::Result<Heightfield, String> {
        let bad = |message: String| format!("{}: {message}", path.display());
        let bytes = twin_fsio::read(path).map_err(|e| e.to_string())?;
        let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        decoder.set_transformations(png::Transformations::EXPAND);
        let mut reader =
            decoder.read_info().map_err(|e| bad(format!("not a readable PNG ({e}): give a grayscale PNG")))?;
        let mut buf = vec![0; reader.output_buffer_size().ok_or_else(|| bad("the PNG is too large".into()))?];
        let info = reader.next_frame(&mut buf).map_err(|e| bad(format!("PNG data unreadable ({e})")))?;
        let (w, h) = (info.width as usize, info.height as usize);
        if w < 2 || h < 2 {
            return Err(bad(format!("a {w}×{h} image is no heightmap: give at least 2×2 pixels")));
        }
        let channels = info.color_type.samples();
        let wide = info.bit_depth == png::BitDepth::Sixteen;
        let max = if wide { 65535.0 } else { 255.0 };
        let sample = |k: usize| -> f64 {
            if wide { f64::from(u16::from_be_bytes([buf[2 * k], buf[2 * k + 1]])) } else { f64::from(buf[k]) }
        };
        let mut heights_m = vec![0.0; w * h];
        for r in 0..h {
            for c in 0..w {
                let base = (r * w + c) * channels;
                let v = sample(base);
                if matches!(info.color_type, png::ColorType::Rgb | png::ColorType::Rgba)
                    && (sample(base + 1) != v || sample(base + 2) != v)
                {
                    return Err(bad(format!(
                        "pixel (row {r}, column {c}) has colour: a heightmap is grayscale (save the image as grayscale)"
                    )));
                }
                // MuJoCo's row 0 is at −y: the image's bottom row.
                heights_m[(h - 1 - r) * w + c] = center_m[2] + v / max * size_m[2];
            }
        }
        Ok(Heightfield {
            center_m: [center_m[0], center_m[1]],
            half_m: [size_m[0] / 2.0, size_m[1] / 2.0],
            yaw_rad,
            nrow: h,
            ncol: w,
            heights_m,
        })
    }
}
