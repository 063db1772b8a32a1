//! Small helpers the library's modules share, each defined once: the workspace's root
//! directory, a scoped thread pool ([`par_map`]), the median, and a golden-section search.

use std::path::{Path, PathBuf};

/// The workspace root (the parent of host-tests).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// Apply `f` to every item on all cores (`std::thread::scope`), keeping the order.
pub fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(items.len())
        .max(1);
    if threads == 1 {
        return items.iter().map(&f).collect();
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut out: Vec<Option<R>> = (0..items.len()).map(|_| None).collect();
    let results = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(item) = items.get(i) else { break };
                    let r = f(item);
                    if let Ok(mut v) = results.lock() {
                        v.push((i, r));
                    }
                }
            });
        }
    });
    for (i, r) in results.into_inner().unwrap_or_default() {
        if let Some(slot) = out.get_mut(i) {
            *slot = Some(r);
        }
    }
    out.into_iter().flatten().collect()
}

/// [`par_map`] with the items started costliest first (`cost`, larger first; ties keep their
/// order), the results in the items' order: with a few jobs of unequal size on two cores, the
/// longest started last would keep one core busy while the other waits.
pub fn par_map_costliest_first<T: Sync, R: Send, K: Ord>(
    items: &[T],
    cost: impl Fn(&T) -> K,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(cost(&items[i])));
    let done = par_map(&order, |&i| f(&items[i]));
    let mut out: Vec<Option<R>> = (0..items.len()).map(|_| None).collect();
    for (i, r) in order.into_iter().zip(done) {
        out[i] = Some(r);
    }
    out.into_iter().flatten().collect()
}

/// The median (reorders `v`); 0 for an empty slice. For an even length, the upper of the two
/// middle values.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let m = v.len() / 2;
    v.select_nth_unstable_by(m, |a, b| a.total_cmp(b));
    v[m]
}

/// Reductions of the bracket in [`golden`] (20 evaluations; our assumption: the bracket shrinks
/// to 0.618^18 = 1.7e-4 of its width, below what the costs it minimises can tell apart).
pub const GOLDEN_ITERATIONS: usize = 18;

/// Golden-section minimum of `f` on `[lo, hi]` clipped to `[a, b]` (20 evaluations).
pub fn golden(lo: f64, hi: f64, a: f64, b: f64, f: impl Fn(f64) -> f64) -> f64 {
    golden_n(lo, hi, a, b, GOLDEN_ITERATIONS, f)
}

/// [`golden`] with `iters` reductions of the bracket (`iters + 2` evaluations).
pub fn golden_n(lo: f64, hi: f64, a: f64, b: f64, iters: usize, f: impl Fn(f64) -> f64) -> f64 {
    golden_below(lo, hi, a, b, iters, |x, _| f(x))
}

/// [`golden_n`] for an `f(x, bound)` that may answer `f64::INFINITY` where it finds its value
/// above `bound` without computing it (it must answer exactly otherwise). Each new point is
/// only compared with the point it competes with, and the loser is dropped, so the bound is
/// that point's value and the search takes the same points and returns the same `x` as with
/// every value computed.
pub fn golden_below(
    lo: f64,
    hi: f64,
    a: f64,
    b: f64,
    iters: usize,
    f: impl Fn(f64, f64) -> f64,
) -> f64 {
    let (mut lo, mut hi) = (lo.max(a), hi.min(b));
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let mut x1 = hi - r * (hi - lo);
    let mut x2 = lo + r * (hi - lo);
    let mut f1 = f(x1, f64::INFINITY);
    let mut f2 = f(x2, f1);
    for _ in 0..iters {
        if f1 < f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - r * (hi - lo);
            f1 = f(x1, f2);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + r * (hi - lo);
            f2 = f(x2, f1);
        }
    }
    if f1 < f2 { x1 } else { x2 }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With a function that answers infinity for every point whose value exceeds the bound it
    /// is given, the bounded search returns the same point, to the bit, as the search with
    /// every value computed, on bumpy functions; and where the minimum lies inside the bracket, some
    /// values are cut (the bound is used).
    #[test]
    fn a_bounded_golden_search_takes_the_same_path() {
        use std::cell::Cell;
        for k in 0..50 {
            let c = 0.37 * k as f64 - 4.0;
            let f = |x: f64| (x - c).powi(2) + 0.3 * (7.0 * x).sin() + 0.01 * (k as f64 * x).cos();
            let cut = Cell::new(0);
            let plain = golden_n(-5.0, 5.0, -6.0, 6.0, GOLDEN_ITERATIONS, f);
            let bounded = golden_below(-5.0, 5.0, -6.0, 6.0, GOLDEN_ITERATIONS, |x, bound| {
                let v = f(x);
                if v > bound {
                    cut.set(cut.get() + 1);
                    f64::INFINITY
                } else {
                    v
                }
            });
            assert_eq!(plain.to_bits(), bounded.to_bits(), "case {k}");
            // (a minimum inside the bracket: the new points lose to their partners by turns)
            if c.abs() < 4.0 {
                assert!(cut.get() > 0, "case {k}: no value was above its bound");
            }
        }
    }
}
