//! SVG plot of a 2D fit in the style of Mann's figures: the curve coloured by signed curvature
//! (red `+κ_s`, green 0, blue `−κ_s`, Mann Fig. 17), data points (red), normals (green segments),
//! interior points (green discs), exterior points (blue discs) and pseudo-normal points (small,
//! orange outside / purple inside). `O(segments + points)` output size.

use std::fmt::Write;

use super::constraints::{Origin, Sample, ValueConstraint};
use crate::polygonize::marching_squares::Polyline;

/// What to draw.
pub struct SvgInput<'a> {
    /// Plot rectangle (input units): lower-left and upper-right.
    pub bounds: ([f64; 2], [f64; 2]),
    /// The curve.
    pub lines: &'a [Polyline],
    /// Curvature per vertex (same shape as `lines`).
    pub kappa: &'a [Vec<f64>],
    /// Curvature mapped to full red/blue (1/input units; Mann uses 5).
    pub kappa_scale: f64,
    /// The user's samples.
    pub samples: &'a [Sample<2>],
    /// Generated constraints to show (pseudo-normal points); may be empty.
    pub extra: &'a [ValueConstraint<2>],
    /// Title text.
    pub title: &'a str,
}

/// `#rrggbb` for curvature `k` (red positive, green 0, blue negative).
pub fn curvature_colour(k: f64, scale: f64) -> String {
    let t = if scale > 0.0 && k.is_finite() {
        (k / scale).clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let (r, g, b) = if t >= 0.0 {
        (t, 1.0 - t, 0.0)
    } else {
        (0.0, 1.0 + t, -t)
    };
    let c = |x: f64| (x * 200.0).round() as u8;
    format!("#{:02x}{:02x}{:02x}", c(r), c(g), c(b))
}

/// Render the plot (800 px on the longer side).
pub fn render(inp: &SvgInput) -> String {
    let (lo, hi) = inp.bounds;
    let ext = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(f64::MIN_POSITIVE);
    let s = 800.0 / ext;
    let (w, h) = ((hi[0] - lo[0]) * s, (hi[1] - lo[1]) * s);
    let tx = |p: &[f64; 2]| ((p[0] - lo[0]) * s, (hi[1] - p[1]) * s);
    let mut o = String::new();
    let _ = writeln!(
        o,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w:.0}" height="{:.0}" viewBox="0 -24 {w:.2} {:.2}">"#,
        h + 24.0,
        h + 24.0
    );
    let _ = writeln!(
        o,
        r#"<rect x="0" y="0" width="{w:.2}" height="{h:.2}" fill="white" stroke="lightgrey"/>"#
    );
    let _ = writeln!(
        o,
        r#"<text x="4" y="-8" font-family="sans-serif" font-size="14">{}</text>"#,
        escape(inp.title)
    );
    for (line, ks) in inp.lines.iter().zip(inp.kappa) {
        let n = line.points.len();
        let segs = if line.closed { n } else { n.saturating_sub(1) };
        for i in 0..segs {
            let (a, b) = (tx(&line.points[i]), tx(&line.points[(i + 1) % n]));
            let k = 0.5 * (ks[i] + ks[(i + 1) % n]);
            let _ = writeln!(
                o,
                r#"<line x1="{:.2}" y1="{:.2}" x2="{:.2}" y2="{:.2}" stroke="{}" stroke-width="2"/>"#,
                a.0,
                a.1,
                b.0,
                b.1,
                curvature_colour(k, inp.kappa_scale)
            );
        }
    }
    let nlen = 0.04 * ext;
    for smp in inp.samples {
        let (x, y) = tx(&smp.p);
        if let Some(nv) = smp.normal {
            let l = nv[0].hypot(nv[1]);
            let q = tx(&[smp.p[0] + nlen * nv[0] / l, smp.p[1] + nlen * nv[1] / l]);
            let _ = writeln!(
                o,
                r#"<line x1="{x:.2}" y1="{y:.2}" x2="{:.2}" y2="{:.2}" stroke="green" stroke-width="1.5"/>"#,
                q.0, q.1
            );
        }
        let fill = if smp.value == 0.0 {
            "red"
        } else if smp.value < 0.0 {
            "green"
        } else {
            "blue"
        };
        let _ = writeln!(
            o,
            r#"<circle cx="{x:.2}" cy="{y:.2}" r="3.5" fill="{fill}"/>"#
        );
    }
    for c in inp.extra {
        if let Origin::PseudoNormal { outside, .. } = c.origin {
            let (x, y) = tx(&c.p);
            let fill = if outside { "orange" } else { "purple" };
            let _ = writeln!(
                o,
                r#"<circle cx="{x:.2}" cy="{y:.2}" r="2" fill="{fill}"/>"#
            );
        }
    }
    o.push_str("</svg>\n");
    o
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_and_elements() {
        assert_eq!(curvature_colour(0.0, 5.0), "#00c800");
        assert_eq!(curvature_colour(10.0, 5.0), "#c80000");
        assert_eq!(curvature_colour(-5.0, 5.0), "#0000c8");
        let lines = [Polyline {
            points: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]],
            closed: true,
        }];
        let kappa = [vec![1.0, 2.0, 3.0]];
        let samples = [Sample {
            p: [0.5, 0.5],
            normal: Some([0.0, 2.0]),
            value: -1.0,
        }];
        let svg = render(&SvgInput {
            bounds: ([0.0, 0.0], [2.0, 1.0]),
            lines: &lines,
            kappa: &kappa,
            kappa_scale: 5.0,
            samples: &samples,
            extra: &[],
            title: "a<b",
        });
        assert_eq!(svg.matches("<line").count(), 4);
        assert!(
            svg.contains("a&lt;b") && svg.contains(r#"fill="green""#) && svg.ends_with("</svg>\n")
        );
    }
}
