//! Latency statistics for `dds_probe`: publishers stamp `header.stamp` with the send time (system
//! clock), subscribers subtract it from the receive time. Both ends run on one host, so they read
//! the same clock.

/// Summary of one-way latencies.
#[derive(Debug, Clone, PartialEq)]
pub struct LatencyStats {
    /// Samples.
    pub count: usize,
    /// Median \[µs\].
    pub p50_us: f64,
    /// 99th percentile \[µs\].
    pub p99_us: f64,
    /// Largest \[µs\].
    pub max_us: f64,
    /// Mean \[µs\].
    pub mean_us: f64,
}

/// The `q`-quantile (0–1) of sorted values, by the nearest-rank method.
pub fn quantile_sorted(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = (q.clamp(0.0, 1.0) * sorted.len() as f64).ceil() as usize;
    Some(sorted[rank.clamp(1, sorted.len()) - 1])
}

/// Statistics of latencies given in nanoseconds; `None` when there are none.
pub fn latency_stats(latencies_ns: &[i64]) -> Option<LatencyStats> {
    let mut us: Vec<f64> = latencies_ns.iter().map(|&ns| ns as f64 / 1e3).collect();
    us.sort_by(f64::total_cmp);
    Some(LatencyStats {
        count: us.len(),
        p50_us: quantile_sorted(&us, 0.5)?,
        p99_us: quantile_sorted(&us, 0.99)?,
        max_us: *us.last()?,
        mean_us: us.iter().sum::<f64>() / us.len() as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_quantiles() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(quantile_sorted(&v, 0.5), Some(50.0));
        assert_eq!(quantile_sorted(&v, 0.99), Some(99.0));
        assert_eq!(quantile_sorted(&v, 1.0), Some(100.0));
        assert_eq!(quantile_sorted(&v, 0.0), Some(1.0));
        assert_eq!(quantile_sorted(&[], 0.5), None);
    }

    #[test]
    fn stats_in_microseconds() {
        let s = latency_stats(&[3_000, 1_000, 2_000]).unwrap();
        assert_eq!((s.count, s.p50_us, s.max_us, s.mean_us), (3, 2.0, 3.0, 2.0));
        assert!(latency_stats(&[]).is_none());
    }
}
