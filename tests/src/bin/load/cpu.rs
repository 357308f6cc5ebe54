//! CPU time from `/proc`: of the server, its control-loop thread, this process, the machine and
//! the loop's core; and the other real-time threads running.

use nanopush_e2e::procfs::{cpu_jiffies, status_field};

/// Clock ticks a second (the unit of /proc's CPU times).
fn clk_tck() -> f64 {
    // SAFETY: sysconf with a valid name has no preconditions.
    let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if t > 0 { t as f64 } else { 100.0 }
}

/// The fields of a /proc/…/stat line after the command name (field 3, the state, is index 0).
fn stat_fields(path: &str) -> Option<Vec<String>> {
    let s = std::fs::read_to_string(path).ok()?;
    let rest = &s[s.rfind(')')? + 1..];
    Some(rest.split_whitespace().map(str::to_string).collect())
}

/// utime + stime (s) of a process or thread.
fn cpu_seconds(path: &str) -> Option<f64> {
    let f = stat_fields(path)?;
    let ut: f64 = f.get(11)?.parse().ok()?;
    let st: f64 = f.get(12)?.parse().ok()?;
    Some((ut + st) / clk_tck())
}

/// The thread of `pid` named `name`.
pub fn find_thread(pid: u32, name: &str) -> Option<u32> {
    std::fs::read_dir(format!("/proc/{pid}/task"))
        .ok()?
        .flatten()
        .find_map(|e| {
            let tid: u32 = e.file_name().to_str()?.parse().ok()?;
            let comm = std::fs::read_to_string(format!("/proc/{pid}/task/{tid}/comm")).ok()?;
            (comm.trim() == name).then_some(tid)
        })
}

/// Machine-wide CPU time from /proc/stat's first line: (busy, steal), in seconds.
fn machine_cpu() -> Option<(f64, f64)> {
    let v = cpu_jiffies(&std::fs::read_to_string("/proc/stat").ok()?, None)?;
    // user nice system idle iowait irq softirq steal (guest time is inside user).
    let total: u64 = v.iter().take(8).sum();
    let idle = v.get(3)? + v.get(4)?;
    let steal = *v.get(7)?;
    let t = clk_tck();
    Some(((total - idle) as f64 / t, steal as f64 / t))
}

/// One core's CPU time from /proc/stat: (irq + softirq, steal), in seconds.
fn core_cpu(core: usize) -> Option<(f64, f64)> {
    let v = cpu_jiffies(&std::fs::read_to_string("/proc/stat").ok()?, Some(core))?;
    let t = clk_tck();
    Some(((v.get(5)? + v.get(6)?) as f64 / t, *v.get(7)? as f64 / t))
}

/// The core a thread last ran on (the loop is pinned, so its core).
pub fn thread_core(pid: u32, tid: u32) -> Option<usize> {
    stat_fields(&format!("/proc/{pid}/task/{tid}/stat"))?
        .get(36)?
        .parse()
        .ok()
}

/// One reading of the CPU times (s) the window takes differences of.
#[derive(Debug, Clone, Copy, Default)]
pub struct CpuSample {
    pub server: f64,
    pub loop_thread: f64,
    pub loop_nvcsw: u64,
    pub bench: f64,
    pub busy: f64,
    pub steal: f64,
    pub core_irq: f64,
    pub core_steal: f64,
}

/// The CPU times now: of the server `pid`, its loop thread, this process, the machine, and the
/// loop's core.
pub fn cpu_sample(pid: u32, loop_tid: Option<u32>, core: Option<usize>) -> CpuSample {
    let (busy, steal) = machine_cpu().unwrap_or_default();
    let (core_irq, core_steal) = core.and_then(core_cpu).unwrap_or_default();
    let task = loop_tid.map(|t| format!("/proc/{pid}/task/{t}"));
    CpuSample {
        server: cpu_seconds(&format!("/proc/{pid}/stat")).unwrap_or(0.0),
        loop_thread: task
            .as_ref()
            .and_then(|t| cpu_seconds(&format!("{t}/stat")))
            .unwrap_or(0.0),
        loop_nvcsw: task
            .as_ref()
            .and_then(|t| status_field(&format!("{t}/status"), "nonvoluntary_ctxt_switches"))
            .unwrap_or(0),
        bench: cpu_seconds("/proc/self/stat").unwrap_or(0.0),
        busy,
        steal,
        core_irq,
        core_steal,
    }
}

/// User-space threads running SCHED_FIFO or SCHED_RR outside `except` (pid): "pid/comm".
pub fn other_realtime_threads(except: u32) -> Vec<String> {
    let mut out = Vec::new();
    let Ok(procs) = std::fs::read_dir("/proc") else {
        return out;
    };
    for p in procs.flatten() {
        let Some(pid) = p.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else {
            continue;
        };
        // Kernel threads have an empty command line.
        if pid == except || std::fs::read(format!("/proc/{pid}/cmdline")).map_or(true, |c| c.is_empty()) {
            continue;
        }
        let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
            continue;
        };
        for t in tasks.flatten() {
            let path = format!("/proc/{pid}/task/{}/stat", t.file_name().to_string_lossy());
            // Field 41 (policy) is index 38 after the name; 1 = SCHED_FIFO, 2 = SCHED_RR.
            if let Some(f) = stat_fields(&path)
                && matches!(f.get(38).map(String::as_str), Some("1" | "2"))
            {
                let comm = std::fs::read_to_string(format!("/proc/{pid}/comm")).unwrap_or_default();
                out.push(format!("{pid}/{}", comm.trim()));
                break;
            }
        }
    }
    out
}
