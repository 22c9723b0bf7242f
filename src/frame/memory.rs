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

/// Resident growth that keeps going: the post-warm-up samples cut into three consecutive
/// windows, each window's floor (its smallest resident set), and the smaller of the two rises
/// from one floor to the next, as a fraction of the first sample. A leak lifts every floor; a
/// pool or arena that steps up once lifts one, and a transient peak (a frame's scratch
/// allocations, freed again) lifts none, so this tells them apart where [`growth_after`]'s
/// peak cannot. `None` without resident figures or with fewer than six samples after warm-up.
pub fn sustained_resident_growth(samples: &[MemorySample], warmup_frames: u32) -> Option<f64> {
    let after: Vec<u64> = samples
        .iter()
        .filter(|s| s.frame >= warmup_frames)
        .map(|s| s.resident_bytes)
        .collect::<Option<_>>()?;
    if after.len() < 6 {
        return None;
    }
    let base = after[0].max(1) as f64;
    let third = after.len() / 3;
    let floor = |window: &[u64]| *window.iter().min().expect("non-empty window") as f64;
    let floors = [
        floor(&after[..third]),
        floor(&after[third..2 * third]),
        floor(&after[2 * third..]),
    ];
    Some((floors[1] - floors[0]).min(floors[2] - floors[1]) / base)
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
    fn a_steady_leak_is_sustained_growth_and_a_step_or_a_peak_is_not() {
        let leak: Vec<MemorySample> = (0..=11)
            .map(|i| sample(i * 20, 1000 + 10 * i as u64, 0))
            .collect();
        // Floors 1000, 1040, 1080 of a first sample of 1000.
        let g = sustained_resident_growth(&leak, 0).unwrap();
        assert!((g - 0.04).abs() < 1e-9, "{g}");
        let step: Vec<MemorySample> = (0..=11)
            .map(|i| sample(i * 20, if i >= 5 { 1030 } else { 1000 }, 0))
            .collect();
        assert_eq!(sustained_resident_growth(&step, 0), Some(0.0));
        // A transient peak in every window (freed the next sample) is no growth.
        let peaks: Vec<MemorySample> = (0..=11)
            .map(|i| sample(i * 20, if i % 4 == 1 { 1030 } else { 1000 }, 0))
            .collect();
        assert_eq!(sustained_resident_growth(&peaks, 0), Some(0.0));
        assert!(sustained_resident_growth(&leak[..5], 0).is_none());
    }

    #[test]
    fn this_process_has_a_resident_set() {
        if cfg!(target_os = "linux") {
            let bytes = resident_bytes().expect("statm on Linux");
            assert!(bytes > 1 << 20, "{bytes}");
        }
    }
}
