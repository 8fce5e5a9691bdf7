//! Element-wise ReLU pieces, in parallel chunks (candle's CPU element-wise ops run on one
//! thread and allocate a tensor per step: `dy * (out > 0)` is three passes there).

use rayon::prelude::*;

const CHUNK: usize = 1 << 15;

/// `v = max(v, 0)` in place.
pub fn relu_inplace(v: &mut [f32]) {
    v.par_chunks_mut(CHUNK)
        .for_each(|c| c.iter_mut().for_each(|x| *x = x.max(0.0)));
}

/// `max(a + b, 0)`.
pub fn add_relu(a: &[f32], b: &[f32]) -> Result<Vec<f32>, String> {
    zip_map("add_relu", a, b, |a, b| (a + b).max(0.0))
}

/// Input gradient of a ReLU from its output: `dy · [out > 0]`.
pub fn relu_backward(out: &[f32], dy: &[f32]) -> Result<Vec<f32>, String> {
    zip_map(
        "relu_backward",
        out,
        dy,
        |o, g| if o > 0.0 { g } else { 0.0 },
    )
}

/// `f(a[i], b[i])` for two equally long slices, in parallel chunks.
fn zip_map(
    name: &str,
    a: &[f32],
    b: &[f32],
    f: impl Fn(f32, f32) -> f32 + Sync,
) -> Result<Vec<f32>, String> {
    if a.len() != b.len() {
        return Err(format!("{name}: {} vs {} values", a.len(), b.len()));
    }
    let mut out = vec![0f32; a.len()];
    out.par_chunks_mut(CHUNK)
        .zip(a.par_chunks(CHUNK).zip(b.par_chunks(CHUNK)))
        .for_each(|(o, (a, b))| {
            for ((o, a), b) in o.iter_mut().zip(a).zip(b) {
                *o = f(*a, *b);
            }
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relu_pieces() {
        let a: Vec<f32> = (0..70_000).map(|i| (i as f32 * 0.37).sin()).collect();
        let b: Vec<f32> = (0..70_000).map(|i| (i as f32 * 0.11).cos() * 0.5).collect();
        let y = add_relu(&a, &b).unwrap();
        assert!(
            y.iter()
                .zip(a.iter().zip(&b))
                .all(|(y, (a, b))| *y == (a + b).max(0.0))
        );
        let d = relu_backward(&y, &a).unwrap();
        assert!(
            d.iter()
                .zip(y.iter().zip(&a))
                .all(|(d, (y, g))| *d == if *y > 0.0 { *g } else { 0.0 })
        );
        let mut r = a.clone();
        relu_inplace(&mut r);
        assert!(r.iter().zip(&a).all(|(r, a)| *r == a.max(0.0)));
        assert!(add_relu(&a, &b[1..]).is_err() && relu_backward(&a[1..], &b).is_err());
    }
}
