//! Pareto fronts: which settings of a sweep no other setting beats on both cost
//! (file bytes, frame time: lower is better) and quality (PSNR: higher is better).

use crate::rows::ParetoRow;

/// Marks the points of `points` — `(cost, quality)` pairs, cost lower-is-better and
/// quality higher-is-better — that are on the Pareto front: `true` for every point
/// that no other point dominates. A point dominates another if its cost is ≤ and its
/// quality ≥ the other's, at least one of them strictly.
///
/// * Exact ties (identical cost and identical quality) do not dominate each other:
///   if one of them is on the front, all of them are.
/// * A point with a non-finite cost or quality (NaN, ±∞) is never on the front and
///   never dominates another point.
///
/// `O(n log n)`: one sort by cost, then one pass keeping the best quality seen at a
/// strictly lower cost.
#[must_use]
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<bool> {
    let mut on_front = vec![false; points.len()];
    let mut order: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    order.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0));

    // Best quality among the points of strictly lower cost than the current group.
    let mut best_cheaper = f64::NEG_INFINITY;
    let mut start = 0;
    while start < order.len() {
        // One group: the points of equal cost (`==`, so -0.0 and 0.0 group together).
        let cost = points[order[start]].0;
        let end = start
            + order[start..]
                .iter()
                .take_while(|&&i| points[i].0 == cost)
                .count();
        let group = &order[start..end];
        let best_here = group
            .iter()
            .map(|&i| points[i].1)
            .fold(f64::NEG_INFINITY, f64::max);
        // Within the group only the best quality survives (ties all of them); it must
        // also beat every cheaper point strictly, or that cheaper point dominates it.
        if best_here > best_cheaper {
            for &i in group {
                on_front[i] = points[i].1 == best_here;
            }
        }
        best_cheaper = best_cheaper.max(best_here);
        start = end;
    }
    on_front
}

/// PSNR differences below this are not told apart on a front, dB.
pub const PSNR_RESOLUTION_DB: f64 = 0.01;

/// Sets [`ParetoRow::front_bytes`] (cost: `file_bytes`, quality: `scores.psnr_db`)
/// and [`ParetoRow::front_frame`] (cost: `gpu_frame_ms_512`, quality:
/// `scores.psnr_db`; rows without a GPU frame time are not on that front) of every
/// row, with [`pareto_front`]'s rules. PSNR is compared at
/// [`PSNR_RESOLUTION_DB`], the precision reported: an f16 asset 0.001 dB above its
/// 8-bit twin at twice the bytes is not a better trade.
pub fn mark_fronts(rows: &mut [ParetoRow]) {
    let quality = |r: &ParetoRow| (r.scores.psnr_db / PSNR_RESOLUTION_DB).round() * PSNR_RESOLUTION_DB;
    let by_bytes: Vec<(f64, f64)> = rows.iter().map(|r| (r.file_bytes as f64, quality(r))).collect();
    let by_frame: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| (r.gpu_frame_ms_512.unwrap_or(f64::NAN), quality(r)))
        .collect();
    let front_bytes = pareto_front(&by_bytes);
    let front_frame = pareto_front(&by_frame);
    for ((row, bytes), frame) in rows.iter_mut().zip(front_bytes).zip(front_frame) {
        row.front_bytes = bytes;
        row.front_frame = frame;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rows::Scores;

    /// The quadratic definition, to check the sort-based one against.
    fn brute_force(points: &[(f64, f64)]) -> Vec<bool> {
        let finite = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite();
        points
            .iter()
            .map(|p| {
                finite(p)
                    && !points
                        .iter()
                        .any(|q| finite(q) && q.0 <= p.0 && q.1 >= p.1 && (q.0 < p.0 || q.1 > p.1))
            })
            .collect()
    }

    #[test]
    fn synthetic_table_with_ties_and_duplicates() {
        let points = [
            (1.0, 10.0),          // 0: cheapest; front
            (2.0, 20.0),          // 1: front, tied exactly with 2
            (2.0, 20.0),          // 2: front (exact tie)
            (2.0, 15.0),          // 3: equal cost, lower quality: dominated by 1
            (3.0, 20.0),          // 4: equal quality, higher cost: dominated by 1
            (3.0, 20.0),          // 5: dominated duplicate of 4
            (4.0, 30.0),          // 6: front
            (5.0, 25.0),          // 7: dominated by 6
            (f64::NAN, 99.0),     // 8: never on the front, never dominates
            (0.5, f64::NAN),      // 9: never
            (6.0, f64::INFINITY), // 10: never (and does not dominate 11)
            (6.0, 31.0),          // 11: front
            (0.5, 5.0),           // 12: cheapest of all: front
        ];
        let expected = [
            true, true, true, false, false, false, true, false, false, false, false, true, true,
        ];
        assert_eq!(pareto_front(&points), expected);
        assert_eq!(brute_force(&points), expected);
    }

    #[test]
    fn degenerate_inputs() {
        assert!(pareto_front(&[]).is_empty());
        assert_eq!(pareto_front(&[(3.0, 1.0)]), [true]);
        assert_eq!(pareto_front(&[(f64::NAN, f64::NAN)]), [false]);
        assert_eq!(
            pareto_front(&[(f64::NEG_INFINITY, 1.0), (1.0, 1.0)]),
            [false, true]
        );
        // Equal cost, different quality; equal quality, different cost.
        assert_eq!(pareto_front(&[(1.0, 1.0), (1.0, 2.0)]), [false, true]);
        assert_eq!(pareto_front(&[(2.0, 1.0), (1.0, 1.0)]), [false, true]);
        // -0.0 and 0.0 are the same cost.
        assert_eq!(pareto_front(&[(-0.0, 1.0), (0.0, 2.0)]), [false, true]);
        assert_eq!(pareto_front(&[(0.0, 2.0), (-0.0, 2.0)]), [true, true]);
    }

    #[test]
    fn matches_the_definition_on_a_grid_with_many_ties() {
        // Deterministic pseudo-random points on a coarse grid, so ties are common.
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % 6) as f64
        };
        for n in 0..40 {
            let points: Vec<(f64, f64)> = (0..n).map(|_| (next(), next())).collect();
            assert_eq!(pareto_front(&points), brute_force(&points), "{points:?}");
        }
    }

    #[test]
    fn fronts_do_not_tell_apart_psnr_below_the_reported_precision() {
        // An f16 twin 0.002 dB above its 8-bit asset at twice the bytes is dominated.
        let mut rows = vec![
            row("u8", 1_000, 30.001, Some(5.0)),
            row("f16", 2_000, 30.003, Some(5.0)),
        ];
        mark_fronts(&mut rows);
        assert!(rows[0].front_bytes && !rows[1].front_bytes);
        // Equal rounded PSNR and equal frame time: both stay (exact ties).
        assert!(rows[0].front_frame && rows[1].front_frame);
        // A real gain is a real trade.
        let mut rows = vec![row("u8", 1_000, 30.0, None), row("f16", 2_000, 30.1, None)];
        mark_fronts(&mut rows);
        assert!(rows[0].front_bytes && rows[1].front_bytes);
    }

    fn row(id: &str, bytes: u64, psnr: f64, frame: Option<f64>) -> ParetoRow {
        ParetoRow {
            id: id.into(),
            resolution: 64,
            rank: 8,
            encoding: "u8".into(),
            voxels: 1,
            file_bytes: bytes,
            bake_secs: 1.0,
            scores: Scores {
                psnr_db: psnr,
                ..Scores::default()
            },
            cpu_render_ms: 1.0,
            gpu_frame_ms_512: frame,
            gpu_frame_ms_1080p: None,
            gpu_adapter: None,
            thumbnail: None,
            front_bytes: false,
            front_frame: false,
        }
    }

    #[test]
    fn marks_both_fronts_of_rows() {
        let mut rows = vec![
            row("a", 100, 20.0, Some(5.0)),
            row("b", 200, 25.0, Some(1.0)),
            row("c", 300, 24.0, None),
            row("d", 50, 10.0, Some(9.0)),
        ];
        mark_fronts(&mut rows);
        let bytes: Vec<bool> = rows.iter().map(|r| r.front_bytes).collect();
        let frame: Vec<bool> = rows.iter().map(|r| r.front_frame).collect();
        assert_eq!(bytes, [true, true, false, true]);
        assert_eq!(frame, [false, true, false, false]);
    }
}
