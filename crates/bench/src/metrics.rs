//! CPU time and memory of this process, for the benchmarks' reports (Linux; `None`
//! elsewhere).

use std::time::Instant;

/// Whose CPU time [`cpu_seconds`] reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clock {
    /// All threads of this process.
    Process,
    /// The calling thread only.
    Thread,
}

/// CPU seconds used so far, unaffected by time spent waiting for a core (vDSO
/// `clock_gettime`).
pub fn cpu_seconds(clock: Clock) -> Option<f64> {
    #[cfg(target_os = "linux")]
    {
        use rustix::time::{clock_gettime, ClockId};
        let t = clock_gettime(match clock {
            Clock::Process => ClockId::ProcessCPUTime,
            Clock::Thread => ClockId::ThreadCPUTime,
        });
        Some(t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = clock;
        None
    }
}

/// Wall and thread CPU seconds of `f`.
pub fn timed<R>(f: impl FnOnce() -> R) -> (R, f64, Option<f64>) {
    timed_on(Clock::Thread, f)
}

/// Wall seconds of `f` and the CPU seconds `clock` counts while it runs.
pub fn timed_on<R>(clock: Clock, f: impl FnOnce() -> R) -> (R, f64, Option<f64>) {
    let c0 = cpu_seconds(clock);
    let t0 = Instant::now();
    let r = f();
    let wall = t0.elapsed().as_secs_f64();
    let cpu = cpu_seconds(clock).zip(c0).map(|(c1, c0)| c1 - c0);
    (r, wall, cpu)
}

/// Resident set size of this process now, bytes (`/proc/self/statm` pages × the page size).
pub fn rss_bytes() -> Option<u64> {
    #[cfg(target_os = "linux")]
    {
        let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
        let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
        Some(pages * rustix::param::page_size() as u64)
    }
    #[cfg(not(target_os = "linux"))]
    {
        None
    }
}

/// Peak resident set size of this process so far, bytes (`VmHWM` of `/proc/self/status`).
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(target_os = "linux")]
    #[test]
    fn clocks_and_memory_are_read_and_grow() {
        let (sum, wall, cpu) = timed(|| (0..2_000_000u64).map(|i| i ^ (i >> 3)).sum::<u64>());
        assert!(sum > 0 && wall >= 0.0);
        assert!(cpu.is_some_and(|c| c >= 0.0));
        let rss = rss_bytes().unwrap_or(0);
        let peak = peak_rss_bytes().unwrap_or(0);
        assert!(rss > 0 && peak >= rss, "rss {rss}, peak {peak}");
        assert!(cpu_seconds(Clock::Process) >= cpu_seconds(Clock::Thread));
    }
}
