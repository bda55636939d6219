//! Sharding shared by `clevrtex sample` and `clevrtex generate`: which indices this process
//! makes, from `--shard K/N` or the cluster's array-job variables.

/// A shard that cannot be worked out: the message names the flag or variable and what to do.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ShardError(pub String);

/// Shown in `--help` of every command that shards.
pub const SHARD_HELP: &str = "Sharding: `--shard K/N` keeps the indices with `index % N == K`, so \
N shards together make every index exactly once. Without `--shard`, the shard comes from \
SLURM_ARRAY_TASK_ID (minus SLURM_ARRAY_TASK_MIN, divided by SLURM_ARRAY_TASK_STEP, when set) \
and SLURM_ARRAY_TASK_COUNT, or \
from JOB_COMPLETION_INDEX (Kubernetes indexed jobs) with the count from `--shard-count`.";

/// Which share of the indices this process makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This shard, `0 <= k < n`.
    pub k: u64,
    /// Number of shards.
    pub n: u64,
}

impl Shard {
    /// The first index of `start..end` in this shard (`end` when there is none).
    fn first(self, start: u64, end: u64) -> u64 {
        if start >= end {
            end
        } else {
            start + (self.k + self.n - start % self.n) % self.n
        }
    }

    /// How many indices of `start..end` are in this shard (without listing them).
    pub fn count(self, start: u64, end: u64) -> u64 {
        (end - self.first(start, end).min(end)).div_ceil(self.n)
    }

    /// The `i`-th index of `start..end` in this shard (`i < count`), without listing them.
    pub fn nth(self, start: u64, end: u64, i: u64) -> u64 {
        self.first(start, end) + i * self.n
    }

    /// Whether `index` is one of the indices of `start..end` in this shard.
    pub fn contains(self, start: u64, end: u64, index: u64) -> bool {
        (start..end).contains(&index) && index % self.n == self.k
    }

    /// The indices of `start..end` in this shard, in order.
    pub fn indices(self, start: u64, end: u64) -> Vec<u64> {
        self.iter(start, end).collect()
    }

    /// The indices of `start..end` in this shard, in order, one at a time (a billion of them
    /// cost no memory).
    pub fn iter(self, start: u64, end: u64) -> impl Iterator<Item = u64> {
        (self.first(start, end)..end).step_by(self.n as usize)
    }
}

/// Parse `K/N`.
fn parse_shard(text: &str, origin: &str) -> Result<Shard, ShardError> {
    let parsed = text
        .split_once('/')
        .and_then(|(k, n)| Some((k.trim().parse().ok()?, n.trim().parse().ok()?)));
    match parsed {
        Some((k, n)) if n > 0 && k < n => Ok(Shard { k, n }),
        _ => Err(ShardError(format!(
            "invalid shard `{text}` from {origin}\nhint: give `K/N` with 0 <= K < N, e.g. `--shard 0/4`"
        ))),
    }
}

fn env_u64(name: &str) -> Result<Option<u64>, ShardError> {
    match std::env::var(name) {
        Ok(v) => v.trim().parse().map(Some).map_err(|_| {
            ShardError(format!("environment variable `{name}` is `{v}`, not a whole number\nhint: unset it or pass `--shard K/N`"))
        }),
        Err(_) => Ok(None),
    }
}

/// `--shard`, else SLURM array variables, else JOB_COMPLETION_INDEX, else everything.
/// `--shard-count` (the flag, not `CLEVRTEX_SHARD_COUNT`, which a job's whole environment may
/// carry) where the shard does not come from JOB_COMPLETION_INDEX means nothing: refused.
pub fn resolve(shard: Option<&str>, shard_count: Option<u64>) -> Result<Shard, ShardError> {
    let resolved = resolve_any(shard, shard_count)?;
    let from_index = shard.is_none()
        && std::env::var_os("SLURM_ARRAY_TASK_ID").is_none()
        && std::env::var_os("JOB_COMPLETION_INDEX").is_some();
    if let (Some(n), false) = (shard_count, from_index) {
        if std::env::var_os("CLEVRTEX_SHARD_COUNT").is_none() {
            let source = match shard {
                Some(s) => format!("`--shard {s}` gives the shard"),
                None if std::env::var_os("SLURM_ARRAY_TASK_ID").is_some() => {
                    "the SLURM array variables give the shard".to_string()
                }
                None => "JOB_COMPLETION_INDEX is not set".to_string(),
            };
            return Err(ShardError(format!(
                "`--shard-count {n}` counts the shards of an indexed job (JOB_COMPLETION_INDEX), and {source}: the flag would be ignored\nhint: pass `--shard K/N` to make one shard here, or leave `--shard-count` out"
            )));
        }
    }
    Ok(resolved)
}

fn resolve_any(shard: Option<&str>, shard_count: Option<u64>) -> Result<Shard, ShardError> {
    if let Some(s) = shard {
        return parse_shard(s, "`--shard`");
    }
    match (
        env_u64("SLURM_ARRAY_TASK_ID")?,
        env_u64("SLURM_ARRAY_TASK_COUNT")?,
    ) {
        (Some(id), Some(count)) => {
            // Task ids run min, min + step, ... (`--array=0-10:2`), so the shard is the
            // position in that sequence, not `id - min`.
            let min = env_u64("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let step = env_u64("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
            let k = match id.checked_sub(min) {
                Some(d) if d % step == 0 => d / step,
                _ => u64::MAX,
            };
            return parse_shard(
                &format!("{k}/{count}"),
                "(SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN) / SLURM_ARRAY_TASK_STEP and SLURM_ARRAY_TASK_COUNT",
            );
        }
        (Some(id), None) => return Err(ShardError(format!(
            "SLURM_ARRAY_TASK_ID is `{id}` but SLURM_ARRAY_TASK_COUNT is not set, so the number of shards is unknown\nhint: pass `--shard K/N`, or unset SLURM_ARRAY_TASK_ID to make every index"
        ))),
        _ => {}
    }
    if let Some(k) = env_u64("JOB_COMPLETION_INDEX")? {
        let Some(n) = shard_count else {
            return Err(ShardError(format!("JOB_COMPLETION_INDEX is `{k}` but the number of shards is unknown\nhint: pass `--shard-count N` or set CLEVRTEX_SHARD_COUNT to the job's completion count")));
        };
        return parse_shard(&format!("{k}/{n}"), "JOB_COMPLETION_INDEX / --shard-count");
    }
    Ok(Shard { k: 0, n: 1 })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_partition_any_range() {
        for (start, end) in [(0, 10), (3, 17), (5, 5), (7, 8), (1000, 1031)] {
            for n in 1..5 {
                let mut all: Vec<u64> = (0..n)
                    .flat_map(|k| Shard { k, n }.indices(start, end))
                    .collect();
                all.sort();
                assert_eq!(
                    all,
                    (start..end).collect::<Vec<_>>(),
                    "{start}..{end} in {n}"
                );
                for k in 0..n {
                    let shard = Shard { k, n };
                    let list = shard.indices(start, end);
                    assert!(list.iter().all(|i| i % n == k));
                    // The list's length, members and order without the list.
                    assert_eq!(shard.count(start, end), list.len() as u64);
                    for (i, &index) in list.iter().enumerate() {
                        assert_eq!(shard.nth(start, end, i as u64), index);
                    }
                    for index in start.saturating_sub(2)..end + 2 {
                        assert_eq!(shard.contains(start, end, index), list.contains(&index));
                    }
                }
            }
        }
    }

    #[test]
    fn explicit_shard_is_parsed_and_checked() {
        assert_eq!(resolve(Some("2/3"), None).unwrap(), Shard { k: 2, n: 3 });
        for bad in ["3/3", "1/0", "x/2", "1"] {
            let err = resolve(Some(bad), None).unwrap_err().to_string();
            assert!(
                err.contains(&format!("`{bad}`")) && err.contains("hint:"),
                "{err}"
            );
        }
    }
}
