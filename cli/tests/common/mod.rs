//! Helpers shared by the command-line tests.

/// Waits for `child`, reading its peak resident memory (VmHWM, a high-water mark, from
/// `/proc/PID/status`) every 5 ms while it runs: its exit status, and the peak in
/// bytes (`None` where there is no /proc).
pub fn wait_with_peak(child: &mut std::process::Child) -> (std::process::ExitStatus, Option<u64>) {
    let status = format!("/proc/{}/status", child.id());
    let mut peak = None;
    loop {
        if let Ok(text) = std::fs::read_to_string(&status) {
            let kb = text
                .lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok());
            if let Some(kb) = kb {
                peak = Some(peak.unwrap_or(0).max(kb * 1024));
            }
        }
        if let Some(exit) = child.try_wait().unwrap() {
            return (exit, peak);
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}
