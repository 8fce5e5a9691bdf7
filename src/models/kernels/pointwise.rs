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
    if a.len() != b.len() {
        return Err(format!("add_relu: {} vs {} values", a.len(), b.len()));
    }
    let mut out = vec![0f32; a.len()];
    out.par_chunks_mut(CHUNK)
        .zip(a.par_chunks(CHUNK).zip(b.par_chunks(CHUNK)))
        .for_each(|(o, (a, b))| {
            for ((o, a), b) in o.iter_mut().zip(a).zip(b) {
                *o = (a + b).max(0.0);
            }
        });
    Ok(out)
}

/// Input gradient of a ReLU from its output: `dy · [out > 0]`.
pub fn relu_backward(out: &[f32], dy: &[f32]) -> Result<Vec<f32>, String> {
    if out.len() != dy.len() {
        return Err(format!(
            "relu_backward: {} vs {} values",
            out.len(),
            dy.len()
        ));
    }
    let mut dx = vec![0f32; dy.len()];
    dx.par_chunks_mut(CHUNK)
        .zip(out.par_chunks(CHUNK).zip(dy.par_chunks(CHUNK)))
        .for_each(|(d, (o, g))| {
            for ((d, o), g) in d.iter_mut().zip(o).zip(g) {
                *d = if *o > 0.0 { *g } else { 0.0 };
            }
        });
    Ok(dx)
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
