//! Pictures of reflectance: a sphere under two lights (a rendered preview of a material) and BRDF slices.

use crate::base::geometry::{spherical, Vec3};
use crate::base::plot::{Canvas, LinePlot, Series, PALETTE};
use crate::stages::brdf::Rgb;
use embedded_graphics::text::Alignment;

/// A BRDF as a function `(wi, wo) → RGB` without the cosine.
pub type BrdfFn<'a> = &'a (dyn Fn(&Vec3, &Vec3) -> Rgb + Sync);

/// Render a sphere of material `f` seen from above (orthographic), lit by a key light from the upper left
/// and a weaker fill light from the right; the surface's x axis (the raster direction's frame) is aligned
/// with the image's horizontal, so anisotropy shows. `size` pixels square, sRGB.
pub fn sphere(f: BrdfFn, size: u32, exposure: f64) -> Canvas {
    let mut cv = Canvas::new(size, size);
    let lights = [
        (Vec3::new(-0.55, 0.55, 0.63).normalize(), 1.0),
        (Vec3::new(0.8, -0.1, 0.59).normalize(), 0.35),
    ];
    let view = Vec3::z();
    let n = size as f64;
    for py in 0..size {
        for px in 0..size {
            let x = (px as f64 + 0.5) / n * 2.0 - 1.0;
            let y = 1.0 - (py as f64 + 0.5) / n * 2.0;
            let r2 = x * x + y * y;
            if r2 >= 1.0 {
                cv.put(px as i64, py as i64, [24, 24, 28]);
                continue;
            }
            let nrm = Vec3::new(x, y, (1.0 - r2).sqrt());
            let t = (Vec3::x() - nrm * nrm.x).normalize();
            let b = nrm.cross(&t);
            let local = |w: &Vec3| Vec3::new(w.dot(&t), w.dot(&b), w.dot(&nrm));
            let wo = local(&view);
            let mut c = [0.0; 3];
            for (l, e) in &lights {
                let wi = local(l);
                if wi.z <= 0.0 || wo.z <= 0.0 {
                    continue;
                }
                let v = f(&wi, &wo);
                for k in 0..3 {
                    c[k] += v[k] * wi.z * e;
                }
            }
            let px_c = c.map(|v| {
                let v = v * exposure;
                let v = v / (1.0 + v);
                (255.0 * v.max(0.0).powf(1.0 / 2.2)).round().clamp(0.0, 255.0) as u8
            });
            cv.put(px as i64, py as i64, px_c);
        }
    }
    cv
}

/// Spheres side by side with captions.
pub fn sphere_row(items: &[(&str, BrdfFn)], size: u32, exposure: f64) -> Canvas {
    let pad = 10;
    let mut cv = Canvas::new(items.len() as u32 * (size + pad) + pad, size + 2 * pad + 16);
    for (k, (label, f)) in items.iter().enumerate() {
        let s = sphere(*f, size, exposure);
        let x = pad + k as u32 * (size + pad);
        cv.blit(&s, x as i64, pad as i64);
        cv.text(
            (x + size / 2) as i32,
            (size + pad + 14) as i32,
            label,
            Alignment::Center,
        );
    }
    cv
}

/// BRDF slices in the plane of incidence: `f·cosθo` (luminance) against the outgoing angle (negative on the
/// incident side) for each incident angle, one panel per angle, one curve per BRDF.
pub fn slices(items: &[(&str, BrdfFn)], incident_deg: &[f64]) -> Canvas {
    let panels: Vec<Canvas> = incident_deg
        .iter()
        .map(|ti| {
            let wi = spherical(ti.to_radians(), 0.0);
            let series = items
                .iter()
                .enumerate()
                .map(|(k, (label, f))| Series {
                    label: label.to_string(),
                    points: (-89..=89)
                        .map(|d| {
                            let t = d as f64;
                            // in the plane of incidence: positive angles on the far (specular) side
                            let wo = spherical(t.abs().to_radians(), if t >= 0.0 { std::f64::consts::PI } else { 0.0 });
                            (t, crate::stages::brdf::luminance(&f(&wi, &wo)) * wo.z)
                        })
                        .collect(),
                    color: PALETTE[k % PALETTE.len()],
                    dashed: k > 0 && k % 2 == 0,
                })
                .collect();
            LinePlot {
                title: format!("incident {ti}°: f·cosθo in the plane of incidence"),
                x_label: "θo (degrees; specular side positive)".into(),
                y_label: "f·cosθo (1/sr)".into(),
                series,
                size_px: (360, 220),
                log_y: false,
                whole_x: false,
            }
            .render()
        })
        .collect();
    Canvas::hstack(&panels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::brdf::Brdf;

    #[test]
    fn sphere_has_a_highlight_where_the_mirror_direction_is() {
        let b = Brdf::parse("ggx:alpha=0.1,material=aluminium").unwrap();
        let f = |wi: &Vec3, wo: &Vec3| b.eval(wi, wo);
        let cv = sphere(&f, 101, 1.0);
        // the key light's half vector with the view: normal ∝ L + z, upper left of centre
        let brightest = cv
            .pixels
            .iter()
            .enumerate()
            .max_by_key(|(_, p)| p[0] as u32 + p[1] as u32 + p[2] as u32)
            .unwrap()
            .0;
        let (x, y) = (brightest % 101, brightest / 101);
        assert!(x < 50 && y < 50, "highlight at ({x}, {y})");
        assert_eq!(cv.pixels[0], [24, 24, 28], "background outside the sphere");
    }
}
