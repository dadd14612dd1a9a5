//! Helpers shared by the tests that record a session of the simulated rig with physics hidden
//! in `[truth.variants]` and compare twins on it (`twin_tracks_hidden_physics.rs`,
//! `twin_tracks_hidden_contact_physics.rs`): the rig descriptions, the session, the twin
//! re-run on the recording, and the per-step scores of a summary.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use crate::cli_support::{default_rig_with, json, rigtwin, text};

/// `f(index, item)` of every item, on as many threads as the machine has cores (at most one
/// per item), in the items' order. The cases of these tests are independent sessions, each a chain of
/// single-threaded processes: one case at a time leaves a core idle. A panic in a case is the
/// test's panic.
pub fn on_every_core<T: Sync, R: Send>(items: &[T], f: impl Fn(usize, &T) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, items.len().max(1));
    let next = AtomicUsize::new(0);
    let results: Vec<Mutex<Option<R>>> = items.iter().map(|_| Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(item) = items.get(i) else { break };
                let r = f(i, item);
                *results[i].lock().unwrap() = Some(r);
            });
        }
    });
    results
        .into_iter()
        .map(|r| r.into_inner().unwrap().expect("every item ran"))
        .collect()
}

/// Every step's largest score (`tests[].steps[].twin.max_score`), in the plan's order.
pub fn max_scores(summary: &serde_json::Value) -> Vec<f64> {
    summary["tests"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|t| t["steps"].as_array().unwrap())
        .map(|s| {
            s["twin"]["max_score"]
                .as_f64()
                .unwrap_or_else(|| panic!("no score: {s}"))
        })
        .collect()
}

/// `physics` with `{t}` standing for the table prefix: once as `truth.variants` (hidden in
/// the rig) and once as `model` (declared to the twin).
pub fn hidden_and_declared(physics: &str) -> String {
    format!(
        "{}\n{}",
        physics.replace("{t}", "truth.variants"),
        physics.replace("{t}", "model")
    )
}

/// A case's folder `dir/name` with two rig descriptions: `rig.toml`, the default rig with
/// `common` and `extra` appended (hidden and declared physics), and `nominal/rig.toml`, the
/// default rig with `common` alone (settings both twins share, e.g. `[twin]`).
pub struct Case {
    pub dir: PathBuf,
    pub rig: PathBuf,
    pub nominal: PathBuf,
}

impl Case {
    pub fn new(dir: &Path, name: &str, common: &str, extra: &str) -> Case {
        let sub = dir.join(name);
        let nominal_dir = sub.join("nominal");
        std::fs::create_dir_all(&nominal_dir).unwrap();
        Case {
            rig: default_rig_with(&sub, &format!("{common}\n{extra}")),
            nominal: default_rig_with(&nominal_dir, common),
            dir: sub,
        }
    }

    /// Runs `plan` (TOML text) on the simulated rig `rig.toml` into `session.mcap`; with
    /// `live_twin` the twin of `rig.toml` runs beside it and the session summary (its scores)
    /// is returned.
    pub fn record(&self, plan: &str, live_twin: bool) -> Option<serde_json::Value> {
        let plan_path = self.dir.join("plan.toml");
        std::fs::write(&plan_path, plan).unwrap();
        let summary = self.dir.join("live.json");
        let mcap = self.mcap();
        let mut args = vec![
            "run",
            self.rig.to_str().unwrap(),
            "--plan",
            plan_path.to_str().unwrap(),
            "--quiet",
            "--out",
            mcap.to_str().unwrap(),
            "--json",
            summary.to_str().unwrap(),
        ];
        if live_twin {
            args.push("--twin");
        }
        let o = rigtwin(&args);
        assert!(o.status.success(), "{}", text(&o));
        live_twin.then(|| json(&summary))
    }

    /// The session log `record` writes.
    pub fn mcap(&self) -> PathBuf {
        self.dir.join("session.mcap")
    }

    /// Re-runs the twin of `config` (its ROM, `[model]` and `[twin]`) on the recording, without
    /// an ensemble, and returns the replay's summary.
    pub fn replay(&self, config: &Path, name: &str) -> serde_json::Value {
        let out = self.dir.join(format!("{name}.json"));
        let o = rigtwin(&[
            "replay",
            self.mcap().to_str().unwrap(),
            "--twin",
            "--config",
            config.to_str().unwrap(),
            "--ensemble",
            "0",
            "--jobs",
            "1",
            "--json",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        json(&out)
    }
}
