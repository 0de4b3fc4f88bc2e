//! Exact Euclidean distance transform (Felzenszwalb and Huttenlocher's lower envelope of parabolas, one
//! pass per axis): how far each cell of a region lies from the nearest cell outside it.

use rayon::prelude::*;

/// 1D squared distance transform of `f` in place: `d(i) = min_j ((i − j)² + f(j))`.
fn dt1(f: &mut [f64], v: &mut Vec<usize>, z: &mut Vec<f64>, d: &mut Vec<f64>) {
    let n = f.len();
    v.clear();
    z.clear();
    d.clear();
    let sep = |q: usize, p: usize, f: &[f64]| {
        ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64))
    };
    for q in 0..n {
        if !f[q].is_finite() {
            continue;
        }
        while let Some(&p) = v.last() {
            let s = sep(q, p, f);
            if s <= *z.last().unwrap_or(&f64::NEG_INFINITY) {
                v.pop();
                z.pop();
            } else {
                v.push(q);
                z.push(s);
                break;
            }
        }
        if v.is_empty() {
            v.push(q);
            z.push(f64::NEG_INFINITY);
        }
    }
    if v.is_empty() {
        return; // no finite value: everything stays infinite
    }
    let mut k = 0;
    for q in 0..n {
        while k + 1 < v.len() && z[k + 1] < q as f64 {
            k += 1;
        }
        let dq = q as f64 - v[k] as f64;
        d.push(dq * dq + f[v[k]]);
    }
    f.copy_from_slice(d);
}

/// Distance, in cells, from every cell of an `nx × ny` row-major grid to the nearest cell where `outside`
/// is true (0 there; infinite when no cell is outside).
pub fn distance_to_outside(outside: &[bool], nx: usize, ny: usize) -> Vec<f64> {
    let mut g: Vec<f64> = outside.iter().map(|&o| if o { 0.0 } else { f64::INFINITY }).collect();
    // columns: transpose, transform rows, transpose back
    let mut t = vec![0.0; nx * ny];
    for j in 0..ny {
        for i in 0..nx {
            t[i * ny + j] = g[j * nx + i];
        }
    }
    t.par_chunks_mut(ny)
        .for_each_init(|| (vec![], vec![], vec![]), |(v, z, d), col| dt1(col, v, z, d));
    for j in 0..ny {
        for i in 0..nx {
            g[j * nx + i] = t[i * ny + j];
        }
    }
    g.par_chunks_mut(nx)
        .for_each_init(|| (vec![], vec![], vec![]), |(v, z, d), row| dt1(row, v, z, d));
    g.par_iter_mut().for_each(|v| *v = v.sqrt());
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_brute_force() {
        let (nx, ny) = (37, 23);
        let mut s = 7u64;
        let outside: Vec<bool> = (0..nx * ny)
            .map(|_| {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (s >> 33) % 17 == 0
            })
            .collect();
        let d = distance_to_outside(&outside, nx, ny);
        for j in 0..ny {
            for i in 0..nx {
                let mut best = f64::INFINITY;
                for jj in 0..ny {
                    for ii in 0..nx {
                        if outside[jj * nx + ii] {
                            let (dx, dy) = (i as f64 - ii as f64, j as f64 - jj as f64);
                            best = best.min((dx * dx + dy * dy).sqrt());
                        }
                    }
                }
                assert!(
                    (d[j * nx + i] - best).abs() < 1e-9,
                    "({i},{j}): {} vs {best}",
                    d[j * nx + i]
                );
            }
        }
    }

    #[test]
    fn nothing_outside_is_infinitely_far() {
        let d = distance_to_outside(&[false; 12], 4, 3);
        assert!(d.iter().all(|v| v.is_infinite()));
    }
}
