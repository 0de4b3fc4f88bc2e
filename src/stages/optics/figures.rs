//! Figures of the optics stage, shared by the verification report and `analyze`.

use super::geometric::MicrofacetBrdf;
use super::wave;
use crate::base::geometry::Vec3;
use crate::base::plot::{Canvas, Heatmap, Scale};

/// The geometric (microfacet) and wave (Kirchhoff, FFT) BRDFs side by side over ψ̄ at incidence `wi`, on
/// `|ψ̄| ≤ 2·max_slope` (the geometric lobe's extent) but never beyond the unit disc of real directions
/// (outside it is grey), log scale, one colour scale for both panels (the larger of their maxima on top).
pub fn wave_vs_geometric_png(slice: &wave::WaveSlice, geo: &MicrofacetBrdf, wi: &Vec3, max_slope: f64) -> Canvas {
    let reach = (2.0 * max_slope).min(1.0);
    let half = ((reach / slice.dpsi).ceil() as usize).clamp(4, slice.m / 2 - 1);
    let k = 2 * half + 1;
    let c = slice.m / 2;
    let mut fw = vec![f64::NAN; k * k];
    let mut fg = vec![f64::NAN; k * k];
    for b in 0..k {
        for a in 0..k {
            let (sa, sb) = (c + a - half, c + b - half);
            if let Some(wo) = slice.wo(sa, sb) {
                fw[b * k + a] = slice.f[sb * slice.m + sa];
                fg[b * k + a] = geo.eval(wi, &wo)[0];
            }
        }
    }
    let top = fw
        .iter()
        .chain(&fg)
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    let ext = half as f64 * slice.dpsi;
    let map = |v: &[f64], title: &str| {
        Heatmap {
            values: v,
            nx: k,
            ny: k,
            x_range: (-ext, ext),
            y_range: (-ext, ext),
            title: title.into(),
            x_label: "ψx (sin θo cos φo at normal incidence)".into(),
            y_label: "ψy".into(),
            value_label: "f (1/sr)".into(),
            scale: Scale::Log { decades: 4.0 },
            value_max: top.is_finite().then_some(top),
            value_min: None,
            plot_px: 420,
            rgb: None,
        }
        .render()
    };
    let (a, b) = (map(&fg, "geometric (microfacet)"), map(&fw, "wave (Kirchhoff, FFT)"));
    Canvas::hstack(&[a, b])
}
