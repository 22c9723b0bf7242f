//! Memory over a long run: the process's resident set and the GPU bytes a method owns,
//! sampled every few frames, so a soak run (`valgi render --frames N --no-write
//! --memory-every K`) and its test can tell a steady state from a leak.

/// One sample of a run's memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemorySample {
    /// Frames finished when the sample was taken.
    pub frame: u32,
    /// Resident set of the process (`None` where the platform does not say).
    pub resident_bytes: Option<u64>,
    /// GPU bytes the method and the views own.
    pub gpu_bytes: u64,
}

impl MemorySample {
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "frame": self.frame,
            "rss_bytes": self.resident_bytes,
            "gpu_bytes": self.gpu_bytes,
        })
    }
}

/// The process's resident set in bytes, from `VmRSS` in `/proc/self/status` (Linux). Driver
/// memory (a software Vulkan's allocations included) is part of it, which is the point: a
/// leak in the driver's state is a leak the user sees.
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// How memory moved after warm-up: the largest resident set and GPU bytes seen after
/// `warmup_frames`, minus the first sample at or after it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Growth {
    /// Resident growth in bytes (negative when memory was given back).
    pub resident_bytes: Option<i64>,
    /// Resident growth as a fraction of the baseline.
    pub resident_fraction: Option<f64>,
    pub gpu_bytes: i64,
    /// Frames between the baseline and the last sample.
    pub frames: u32,
}

/// Growth of `samples` after `warmup_frames`; `None` with fewer than two samples past it.
pub fn growth_after(samples: &[MemorySample], warmup_frames: u32) -> Option<Growth> {
    let after: Vec<&MemorySample> = samples
        .iter()
        .filter(|s| s.frame >= warmup_frames)
        .collect();
    let (first, rest) = after.split_first()?;
    let last = rest.last()?;
    let resident = first.resident_bytes.and_then(|base| {
        let peak = rest.iter().filter_map(|s| s.resident_bytes).max()?;
        Some((base, peak as i64 - base as i64))
    });
    let gpu_peak = rest
        .iter()
        .map(|s| s.gpu_bytes)
        .max()
        .unwrap_or(first.gpu_bytes);
    Some(Growth {
        resident_bytes: resident.map(|(_, d)| d),
        resident_fraction: resident.map(|(base, d)| d as f64 / base.max(1) as f64),
        gpu_bytes: gpu_peak as i64 - first.gpu_bytes as i64,
        frames: last.frame - first.frame,
    })
}

/// Resident growth that keeps going: the post-warm-up samples split into two halves, each
/// half's growth (its peak minus its first sample) as a fraction of the baseline, and the
/// smaller of the two. A leak grows in both halves; a pool or arena that steps up once grows
/// in one, so this tells the two apart where [`growth_after`] alone cannot. `None` without
/// resident figures or with fewer than four samples after warm-up.
pub fn sustained_resident_growth(samples: &[MemorySample], warmup_frames: u32) -> Option<f64> {
    let after: Vec<&MemorySample> = samples
        .iter()
        .filter(|s| s.frame >= warmup_frames)
        .collect();
    if after.len() < 4 {
        return None;
    }
    let base = after[0].resident_bytes? as f64;
    let (first_half, second_half) = after.split_at(after.len() / 2);
    let growth = |half: &[&MemorySample]| -> Option<f64> {
        let start = half.first()?.resident_bytes? as f64;
        let peak = half.iter().filter_map(|s| s.resident_bytes).max()? as f64;
        Some((peak - start) / base.max(1.0))
    };
    // The second half starts where the first ended, so a rise across the boundary counts.
    let mut second = vec![*first_half.last()?];
    second.extend_from_slice(second_half);
    Some(growth(first_half)?.min(growth(&second)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(frame: u32, rss: u64, gpu: u64) -> MemorySample {
        MemorySample {
            frame,
            resident_bytes: Some(rss),
            gpu_bytes: gpu,
        }
    }

    #[test]
    fn growth_ignores_warm_up_and_takes_the_peak() {
        let samples = [
            sample(0, 10, 5),
            sample(50, 100, 7),
            sample(100, 130, 7),
            sample(150, 120, 7),
        ];
        let g = growth_after(&samples, 50).unwrap();
        assert_eq!(g.resident_bytes, Some(30));
        assert_eq!(g.gpu_bytes, 0);
        assert_eq!(g.frames, 100);
        assert!((g.resident_fraction.unwrap() - 0.3).abs() < 1e-12);
        assert!(growth_after(&samples, 150).is_none());
    }

    #[test]
    fn a_steady_leak_is_sustained_growth_and_a_single_step_is_not() {
        let leak: Vec<MemorySample> = (0..=10)
            .map(|i| sample(i * 20, 1000 + 10 * i as u64, 0))
            .collect();
        let g = sustained_resident_growth(&leak, 0).unwrap();
        // 40 in the first half (frames 0–80), 60 in the second (80–200), of 1000.
        assert!((g - 0.04).abs() < 1e-9, "{g}");
        let step: Vec<MemorySample> = (0..=10)
            .map(|i| sample(i * 20, if i >= 3 { 1030 } else { 1000 }, 0))
            .collect();
        assert_eq!(sustained_resident_growth(&step, 0), Some(0.0));
        // A step right at the halves' boundary is still one step.
        let boundary: Vec<MemorySample> = (0..=9)
            .map(|i| sample(i * 20, if i >= 5 { 1030 } else { 1000 }, 0))
            .collect();
        assert_eq!(sustained_resident_growth(&boundary, 0), Some(0.0));
        assert!(sustained_resident_growth(&leak[..3], 0).is_none());
    }

    #[test]
    fn this_process_has_a_resident_set() {
        if cfg!(target_os = "linux") {
            let bytes = resident_bytes().expect("statm on Linux");
            assert!(bytes > 1 << 20, "{bytes}");
        }
    }
}
