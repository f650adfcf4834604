//! Splitting an archive between cluster jobs: `--shard I/N`, or from the job array's environment.

use super::discover::SubjectGroup;

/// Errors reading a shard.
#[derive(Debug, thiserror::Error)]
pub enum ShardError {
    #[error("shard '{0}': expected I/N with 0 ≤ I < N (e.g. 0/4)")]
    Syntax(String),
    #[error("shard '{0}': at most {max} shards", max = MAX_SHARDS)]
    TooMany(String),
    #[error("{var}={value}: expected a non-negative integer")]
    Env { var: &'static str, value: String },
}

/// Most shards a run may be cut into (`--shard I/N`, the job array's environment, and the
/// summaries `merge-reports` joins).
pub const MAX_SHARDS: usize = 100_000;

/// Shard `index` of `count` (0-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = ShardError;
    fn from_str(s: &str) -> Result<Shard, ShardError> {
        let bad = || ShardError::Syntax(s.into());
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) = (i.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
        if count == 0 || index >= count {
            return Err(bad());
        }
        if count > MAX_SHARDS {
            return Err(ShardError::TooMany(s.into()));
        }
        Ok(Shard { index, count })
    }
}

impl Shard {
    /// From the environment when `--shard` is absent: `SLURM_ARRAY_TASK_ID` (minus
    /// `SLURM_ARRAY_TASK_MIN`, default 0) of `SLURM_ARRAY_TASK_COUNT`, or Kubernetes'
    /// `JOB_COMPLETION_INDEX` of `SMOCAP_SHARD_COUNT` (Indexed Jobs do not export their
    /// completions). `None` when neither is set.
    pub fn from_env(get: impl Fn(&str) -> Option<String>) -> Result<Option<Shard>, ShardError> {
        let num = |var: &'static str| -> Result<Option<usize>, ShardError> {
            get(var).map(|v| v.trim().parse().map_err(|_| ShardError::Env { var, value: v })).transpose()
        };
        let pairs = [
            (
                num("SLURM_ARRAY_TASK_ID")?
                    .map(|i| i.saturating_sub(num("SLURM_ARRAY_TASK_MIN").ok().flatten().unwrap_or(0))),
                num("SLURM_ARRAY_TASK_COUNT")?,
            ),
            (num("JOB_COMPLETION_INDEX")?, num("SMOCAP_SHARD_COUNT")?),
        ];
        for (i, n) in pairs {
            if let (Some(index), Some(count)) = (i, n) {
                return format!("{index}/{count}").parse().map(Some);
            }
        }
        Ok(None)
    }
}

/// For each subject, its shard: subjects are kept whole and dealt, heaviest first (by frame count;
/// ties by dataset and subject name), to the shard with the fewest frames so far (ties: lowest
/// index). Deterministic for the same archive.
pub fn assign(groups: &[SubjectGroup], count: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..groups.len()).collect();
    order.sort_by(|&a, &b| {
        let (ga, gb) = (&groups[a], &groups[b]);
        gb.frames().cmp(&ga.frames()).then(ga.dataset.cmp(&gb.dataset)).then(ga.subject.cmp(&gb.subject))
    });
    let mut load = vec![0u64; count.clamp(1, MAX_SHARDS)];
    let mut out = vec![0; groups.len()];
    for g in order {
        let s = (0..load.len()).min_by_key(|&s| (load[s], s)).unwrap_or(0);
        load[s] += groups[g].frames();
        out[g] = s;
    }
    out
}
