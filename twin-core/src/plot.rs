//! Minimal SVG plots (lines, points, shaded bands, marker lines; linear or log axes): the one
//! plotting helper of twin's reports (sysid's calibration and gap reports, `twin log analyze`,
//! success-against-difficulty sweeps of `twin randomize --sweep`). A report builds [`Plot`]
//! panels from its series and [`stack_svg`] renders them into one document. Deterministic
//! text: the same data give the same bytes.

use std::fmt::Write as _;

/// Colours of successive series.
pub const COLORS: [&str; 6] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf"];

enum Item {
    Line { name: String, xy: Vec<(f64, f64)>, color: &'static str },
    Points { name: String, xy: Vec<(f64, f64)>, color: &'static str },
    Band { xlh: Vec<(f64, f64, f64)>, color: &'static str },
    VLine { name: String, x: f64, color: &'static str },
}

/// One panel.
pub struct Plot {
    title: String,
    x_label: String,
    y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    items: Vec<Item>,
}

const W: f64 = 720.0;
const H: f64 = 420.0;
const ML: f64 = 80.0;
const MR: f64 = 150.0;
const MT: f64 = 36.0;
const MB: f64 = 50.0;

impl Plot {
    /// An empty panel.
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Plot {
        Plot {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            log_x: false,
            log_y: false,
            items: Vec::new(),
        }
    }
    /// A polyline.
    pub fn line(&mut self, name: &str, xy: Vec<(f64, f64)>, color: &'static str) {
        self.items.push(Item::Line { name: name.into(), xy, color });
    }
    /// Markers.
    pub fn points(&mut self, name: &str, xy: Vec<(f64, f64)>, color: &'static str) {
        self.items.push(Item::Points { name: name.into(), xy, color });
    }
    /// A shaded band `(x, low, high)`.
    pub fn band(&mut self, xlh: Vec<(f64, f64, f64)>, color: &'static str) {
        self.items.push(Item::Band { xlh, color });
    }

    /// A dashed vertical line across the panel at `x` (an event: a fall's onset).
    pub fn vline(&mut self, name: &str, x: f64, color: &'static str) {
        self.items.push(Item::VLine { name: name.into(), x, color });
    }

    fn tx(&self, v: f64) -> f64 {
        if self.log_x { v.max(1e-300).log10() } else { v }
    }
    fn ty(&self, v: f64) -> f64 {
        if self.log_y { v.max(1e-300).log10() } else { v }
    }

    fn range(&self) -> ([f64; 2], [f64; 2]) {
        let (mut xr, mut yr) = ([f64::INFINITY, f64::NEG_INFINITY], [f64::INFINITY, f64::NEG_INFINITY]);
        let mut add = |x: f64, y: f64| {
            let ok_x = x.is_finite() && (!self.log_x || x > 0.0);
            let ok_y = y.is_finite() && (!self.log_y || y > 0.0);
            if ok_x && ok_y {
                let (x, y) = (self.tx(x), self.ty(y));
                xr = [xr[0].min(x), xr[1].max(x)];
                yr = [yr[0].min(y), yr[1].max(y)];
            }
        };
        for it in &self.items {
            match it {
                Item::Line { xy, .. } | Item::Points { xy, .. } => xy.iter().for_each(|&(x, y)| add(x, y)),
                Item::Band { xlh, .. } => xlh.iter().for_each(|&(x, l, h)| {
                    add(x, l);
                    add(x, h)
                }),
                Item::VLine { .. } => {}
            }
        }
        let pad = |r: [f64; 2]| {
            if !r[0].is_finite() {
                [0.0, 1.0]
            } else if r[1] - r[0] < 1e-12 {
                [r[0] - 0.5, r[1] + 0.5]
            } else {
                let p = 0.04 * (r[1] - r[0]);
                [r[0] - p, r[1] + p]
            }
        };
        (pad(xr), pad(yr))
    }

    /// The panel as an SVG `<g>` at vertical offset `y0`.
    fn render(&self, out: &mut String, y0: f64) {
        let (xr, yr) = self.range();
        let px = |x: f64| ML + (self.tx(x) - xr[0]) / (xr[1] - xr[0]) * (W - ML - MR);
        let py = |y: f64| y0 + MT + (1.0 - (self.ty(y) - yr[0]) / (yr[1] - yr[0])) * (H - MT - MB);
        let ok =
            |x: f64, y: f64| x.is_finite() && y.is_finite() && (!self.log_x || x > 0.0) && (!self.log_y || y > 0.0);
        let _ = writeln!(
            out,
            "<rect x=\"{ML}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#444\"/>",
            y0 + MT,
            W - ML - MR,
            H - MT - MB
        );
        let _ = writeln!(
            out,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"15\">{}</text>",
            (W - MR + ML) / 2.0,
            y0 + 22.0,
            escape(&self.title)
        );
        let _ = writeln!(
            out,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"13\">{}</text>",
            (W - MR + ML) / 2.0,
            y0 + H - 10.0,
            escape(&self.x_label)
        );
        let _ = writeln!(
            out,
            "<text x=\"16\" y=\"{}\" text-anchor=\"middle\" font-size=\"13\" transform=\"rotate(-90 16 {})\">{}</text>",
            y0 + H / 2.0,
            y0 + H / 2.0,
            escape(&self.y_label)
        );
        // Ticks: decades on log axes, 5 even steps on linear ones.
        let ticks = |r: [f64; 2], log: bool| -> Vec<f64> {
            if log {
                (r[0].ceil() as i32..=r[1].floor() as i32).map(|e| 10f64.powi(e)).collect()
            } else {
                (0..=4).map(|i| r[0] + (r[1] - r[0]) * i as f64 / 4.0).collect()
            }
        };
        for x in ticks(xr, self.log_x) {
            let _ = writeln!(
                out,
                "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-size=\"11\">{}</text>",
                px(x),
                y0 + H - MB + 16.0,
                tick_label(x)
            );
        }
        for y in ticks(yr, self.log_y) {
            let _ = writeln!(
                out,
                "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\" font-size=\"11\">{}</text>",
                ML - 4.0,
                py(y) + 4.0,
                tick_label(y)
            );
        }
        let mut legend = 0;
        for it in &self.items {
            match it {
                Item::VLine { name, x, color } => {
                    // Only inside the panel's x range (the range comes from the data).
                    let inside = x.is_finite() && (!self.log_x || *x > 0.0) && (ML..=W - MR).contains(&px(*x));
                    if !inside {
                        continue;
                    }
                    let _ = writeln!(
                        out,
                        "<line x1=\"{x:.1}\" y1=\"{}\" x2=\"{x:.1}\" y2=\"{}\" stroke=\"{color}\" stroke-width=\"1.4\" \
                         stroke-dasharray=\"6 4\"/>",
                        y0 + MT,
                        y0 + H - MB,
                        x = px(*x)
                    );
                    let ly = y0 + MT + 12.0 + 16.0 * legend as f64;
                    let lx = W - MR + 10.0;
                    let _ = writeln!(
                        out,
                        "<line x1=\"{lx}\" y1=\"{ly}\" x2=\"{}\" y2=\"{ly}\" stroke=\"{color}\" stroke-dasharray=\"4 3\"/>\
                         <text x=\"{}\" y=\"{}\" font-size=\"11\">{}</text>",
                        lx + 18.0,
                        lx + 24.0,
                        ly + 4.0,
                        escape(name)
                    );
                    legend += 1;
                }
                Item::Band { xlh, color } => {
                    let pts: Vec<String> = xlh
                        .iter()
                        .filter(|p| ok(p.0, p.2))
                        .map(|&(x, _, h)| format!("{:.1},{:.1}", px(x), py(h)))
                        .chain(
                            xlh.iter()
                                .rev()
                                .filter(|p| ok(p.0, p.1))
                                .map(|&(x, l, _)| format!("{:.1},{:.1}", px(x), py(l))),
                        )
                        .collect();
                    let _ = writeln!(
                        out,
                        "<polygon points=\"{}\" fill=\"{color}\" fill-opacity=\"0.15\" stroke=\"none\"/>",
                        pts.join(" ")
                    );
                }
                Item::Line { name, xy, color } | Item::Points { name, xy, color } => {
                    let is_line = matches!(it, Item::Line { .. });
                    if is_line {
                        let pts: Vec<String> = xy
                            .iter()
                            .filter(|p| ok(p.0, p.1))
                            .map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y)))
                            .collect();
                        let _ = writeln!(
                            out,
                            "<polyline points=\"{}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"1.8\"/>",
                            pts.join(" ")
                        );
                    } else {
                        for &(x, y) in xy.iter().filter(|p| ok(p.0, p.1)) {
                            let _ = writeln!(
                                out,
                                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"2.2\" fill=\"{color}\"/>",
                                px(x),
                                py(y)
                            );
                        }
                    }
                    let ly = y0 + MT + 12.0 + 16.0 * legend as f64;
                    let lx = W - MR + 10.0;
                    let mark = if is_line {
                        format!(
                            "<line x1=\"{lx}\" y1=\"{ly}\" x2=\"{}\" y2=\"{ly}\" stroke=\"{color}\" stroke-width=\"2\"/>",
                            lx + 18.0
                        )
                    } else {
                        format!("<circle cx=\"{}\" cy=\"{ly}\" r=\"3\" fill=\"{color}\"/>", lx + 9.0)
                    };
                    let _ = writeln!(
                        out,
                        "{mark}<text x=\"{}\" y=\"{}\" font-size=\"11\">{}</text>",
                        lx + 24.0,
                        ly + 4.0,
                        escape(name)
                    );
                    legend += 1;
                }
            }
        }
    }
}

fn tick_label(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.0e}")
    } else {
        format!("{:.3}", v).trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// Panels stacked vertically in one SVG document.
pub fn stack_svg(panels: &[Plot]) -> String {
    let height = H * panels.len().max(1) as f64;
    let mut out = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{height}\" viewBox=\"0 0 {W} {height}\" \
         font-family=\"sans-serif\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
    );
    for (i, p) in panels.iter().enumerate() {
        p.render(&mut out, H * i as f64);
    }
    out.push_str("</svg>\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_is_well_formed_and_places_points_inside_the_frame() {
        let mut p = Plot::new("t <1>", "x", "y");
        p.log_x = true;
        p.line("a", vec![(0.1, 1.0), (10.0, 2.0), (-1.0, 3.0)], COLORS[0]);
        p.band(vec![(0.1, 0.5, 1.5), (10.0, 1.5, 2.5)], COLORS[0]);
        let svg = stack_svg(&[p]);
        let doc = roxmltree::Document::parse(&svg).unwrap();
        let poly = doc.descendants().find(|n| n.has_tag_name("polyline")).unwrap();
        let pts: Vec<f64> = poly.attribute("points").unwrap().split([' ', ',']).map(|v| v.parse().unwrap()).collect();
        // Two valid points (the negative x is dropped on a log axis), inside the frame.
        assert_eq!(pts.len(), 4);
        assert!(pts[0] > ML && pts[2] < W - MR && pts[0] < pts[2]);
        assert!(svg.contains("t &lt;1&gt;"));
    }
}
