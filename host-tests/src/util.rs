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

/// Golden-section minimum of `f` on `[lo, hi]` clipped to `[a, b]` (20 evaluations).
pub fn golden(lo: f64, hi: f64, a: f64, b: f64, f: impl Fn(f64) -> f64) -> f64 {
    golden_n(lo, hi, a, b, 18, f)
}

/// [`golden`] with `iters` reductions of the bracket (`iters + 2` evaluations).
pub fn golden_n(lo: f64, hi: f64, a: f64, b: f64, iters: usize, f: impl Fn(f64) -> f64) -> f64 {
    let (mut lo, mut hi) = (lo.max(a), hi.min(b));
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let mut x1 = hi - r * (hi - lo);
    let mut x2 = lo + r * (hi - lo);
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..iters {
        if f1 < f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - r * (hi - lo);
            f1 = f(x1);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + r * (hi - lo);
            f2 = f(x2);
        }
    }
    if f1 < f2 { x1 } else { x2 }
}
