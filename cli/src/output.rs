//! Number formatting for human-readable output.

/// How the command line names a choice (`incoherent`, `cells`), for messages: never
/// the enum's Rust name.
pub(crate) fn choice(value: impl clap::ValueEnum) -> String {
    value.to_possible_value().map_or_else(String::new, |v| v.get_name().to_string())
}

/// `1234567` as `1,234,567`.
pub(crate) fn thousands(n: u64) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// `n` things, with thousands separators and the plural when `n` is not 1:
/// `1 triangle`, `1,234 triangles`, `2 leaves`.
/// `text` safe to print on a terminal: control characters other than line feeds and
/// tabs (escape sequences that clear the screen or set the window title, C1 controls,
/// DEL) and the bidirectional overrides are written as `\u001b`-style escapes. Strings
/// from meshes (material, part, light names, URIs, extension names) reach messages;
/// JSON output keeps them exact (its escapes are JSON's, and a `\u` escape of a
/// character inside a JSON string is that character).
pub(crate) fn printable(text: &str) -> std::borrow::Cow<'_, str> {
    let unsafe_char = |c: char| {
        (c.is_control() && c != '\n' && c != '\t') || matches!(c, '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}')
    };
    if !text.chars().any(unsafe_char) {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len() + 16);
    for c in text.chars() {
        if unsafe_char(c) {
            out.push_str(&format!("\\u{:04x}", c as u32));
        } else {
            out.push(c);
        }
    }
    std::borrow::Cow::Owned(out)
}

/// The most items a count option (rays, points) may ask for: 2^27 (134 million;
/// 4 GiB of rays), checked before anything is allocated.
pub(crate) const MAX_COUNT: usize = 1 << 27;

/// A count option's value, at most [`MAX_COUNT`].
pub(crate) fn parse_count(text: &str) -> Result<usize, String> {
    let n: usize = text.trim().replace('_', "").parse().map_err(|_| format!("'{text}' is not a count"))?;
    if n > MAX_COUNT {
        return Err(format!("{n} is more than the {MAX_COUNT} (2^27) a run may ask for; split the work"));
    }
    Ok(n)
}

/// A number of timed runs: 1 to 1000.
pub(crate) fn parse_runs(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(n) if (1..=1000).contains(&n) => Ok(n),
        _ => Err(format!("'{text}': runs are 1 to 1000")),
    }
}

/// A byte count as the command line gives it: digits with an optional suffix K, M, G
/// or T (powers of 1024; `B` and `iB` accepted after them).
pub(crate) fn parse_bytes(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let t = t.strip_suffix("iB").or_else(|| t.strip_suffix('B')).unwrap_or(t);
    let (digits, shift) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let shift = match c.to_ascii_uppercase() {
                'K' => 10,
                'M' => 20,
                'G' => 30,
                'T' => 40,
                _ => return Err(format!("'{text}': unknown suffix '{c}' (K, M, G or T)")),
            };
            (&t[..i], shift)
        }
        _ => (t, 0),
    };
    let n: u64 = digits.parse().map_err(|_| format!("'{text}' is not a byte count (digits, then K, M, G or T)"))?;
    n.checked_mul(1u64 << shift).ok_or_else(|| format!("'{text}' is more than 2^64 bytes"))
}

pub(crate) fn counted(n: u64, thing: &str) -> String {
    let plural = match thing {
        _ if n == 1 => thing.to_string(),
        "leaf" => "leaves".to_string(),
        "mesh" => "meshes".to_string(),
        _ => format!("{thing}s"),
    };
    format!("{} {plural}", thousands(n))
}

/// Bytes in MB (10^6), one decimal.
pub(crate) fn mb(bytes: u64) -> String {
    format!("{:.1} MB", bytes as f64 / 1e6)
}

/// Writes to stdout, turning a closed pipe into an error the caller can recognise.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), "{}", $crate::output::printable(&format!($($arg)*)))?;
    }};
}

/// Writes a report line to standard output, or to standard error when standard output
/// carries the command's data (`-o -`), so that the two never mix.
#[macro_export]
macro_rules! report {
    ($data_on_stdout:expr, $($arg:tt)*) => {{
        if $data_on_stdout {
            eprintln!("{}", $crate::output::printable(&format!($($arg)*)));
        } else {
            $crate::out!($($arg)*);
        }
    }};
}

/// Whether an output path is `-`: the data goes to standard output.
pub(crate) fn is_stdout(path: &std::path::Path) -> bool {
    path.as_os_str() == "-"
}

/// Writes a command's data to `path` as `octrace_format::write_atomically` does (a
/// symbolic link is written through, a FIFO or device written into, a regular file
/// replaced whole), or to standard output for `-`.
///
/// Data that does not all reach standard output is an error (exit 1): a closed
/// standard output (which Rust's `stdout` would let the writes pass into silently), a
/// pipe its reader closed early (not the broken pipe that text output treats as
/// success: the data is the command's result), a full disk.
pub(crate) fn write_data(path: &std::path::Path, parts: &[&[u8]]) -> anyhow::Result<()> {
    use std::io::Write as _;
    if is_stdout(path) {
        let total: usize = parts.iter().map(|p| p.len()).sum();
        anyhow::ensure!(
            stdout_is_open(),
            "standard output is closed: the {} bytes of -o - were not written",
            thousands(total as u64)
        );
        let mut out = std::io::stdout().lock();
        let mut written = 0usize;
        let result = parts.iter().try_for_each(|part| {
            out.write_all(part)?;
            written += part.len();
            Ok(())
        });
        // The error's text only: a broken pipe here is a failure, not the quiet end
        // `main` gives text output whose reader stopped reading.
        result.and_then(|()| out.flush()).map_err(|e: std::io::Error| {
            anyhow::anyhow!(
                "writing -o - to standard output failed after {} of {} bytes: {e}",
                thousands(written as u64),
                thousands(total as u64)
            )
        })?;
        return Ok(());
    }
    Ok(octrace_format::write_atomically(path, parts)?)
}

/// Whether standard output was open when the process started. Rust's runtime opens
/// `/dev/null` read-write on a standard descriptor that is closed at start (so that no
/// file the program opens lands there), and writes to it then vanish: this looks for
/// that descriptor (a shell's `> /dev/null` opens it write-only, and stays a success).
/// True where the system does not say (no `/proc`).
fn stdout_is_open() -> bool {
    let Ok(target) = std::fs::read_link("/proc/self/fd/1") else { return true };
    if target != std::path::Path::new("/dev/null") {
        return true;
    }
    let Ok(info) = std::fs::read_to_string("/proc/self/fdinfo/1") else { return true };
    let flags = info.lines().find_map(|l| l.strip_prefix("flags:")).and_then(|f| u32::from_str_radix(f.trim(), 8).ok());
    // O_ACCMODE: 2 is O_RDWR.
    flags.is_none_or(|f| f & 3 != 2)
}

/// Refuses an output that is one of the command's inputs (the same file, through
/// symbolic and hard links): writing it would destroy what the command reads. Checked
/// before any work; an output that does not exist yet, or is not a regular file (a
/// FIFO, `/dev/null`), passes.
pub(crate) fn refuse_overwriting(
    output: &std::path::Path,
    option: &str,
    inputs: &[&std::path::Path],
) -> anyhow::Result<()> {
    if is_stdout(output) {
        return Ok(());
    }
    if !std::fs::metadata(output).is_ok_and(|m| m.is_file()) {
        return Ok(());
    }
    for input in inputs {
        if octrace_format::same_file(output, input) {
            anyhow::bail!(
                "{option} {} is the file this command reads as {}: writing it would destroy its input \
                 (nothing was written; choose another output)",
                output.display(),
                input.display()
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_read_as_english() {
        assert_eq!(counted(1, "triangle"), "1 triangle");
        assert_eq!(counted(0, "triangle"), "0 triangles");
        assert_eq!(counted(1, "leaf"), "1 leaf");
        assert_eq!(counted(46_467, "leaf"), "46,467 leaves");
    }
}
