//! `rigtwin firmware-sim`: the rig's electronics, simulated — the other end of `rigtwin run
//! --backend hw`'s links (CAN FD over a UDP tunnel, two pseudo-terminals), driven by the
//! simulated rig and speaking exactly the protocols of `firmware-interfaces/`. Prints one JSON
//! line with where to connect, then one per finished session.

use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;

use crate::config::RigConfig;
use crate::rig::device::{
    FirmwareOptions, FirmwareSim, Inject, LinkFault, Pace, HEARTBEAT_PERIOD, HEARTBEAT_TIMEOUT,
};
use crate::rig::sim::{InjectedFault, SimRig, SimRigSpec};

/// How the device paces its DAQ blocks.
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum PaceArg {
    /// Like a real DAQ: block k leaves at the wall time of its last sample.
    Realtime,
    /// As fast as it computes, at most three blocks ahead of the host (HOST_HEARTBEAT
    /// ConsumedSeq): for tests.
    Virtual,
}

/// `rigtwin firmware-sim`
#[derive(Args, Debug)]
pub struct FirmwareSimArgs {
    /// Rig description (TOML). Without it: the embedded default rig.
    pub config: Option<PathBuf>,
    /// UDP address of the CAN tunnel (loopback by default; port 0: a free port).
    #[arg(long, default_value = "127.0.0.1:0")]
    pub can_listen: SocketAddr,
    /// The simulated rig's clearance / beam length (default: the rig description's); within a
    /// plan's bounds, -1e-4 to 0.1 (0: the probes touch; negative: a pre-load).
    #[arg(long)]
    pub clearance: Option<f64>,
    /// Block pacing.
    #[arg(long, value_enum, default_value = "realtime")]
    pub pace: PaceArg,
    /// Serve one session, then exit.
    #[arg(long)]
    pub once: bool,
    /// Inject a fault, as JSON (repeatable): the simulated rig's (as `rigtwin run --inject`)
    /// or a link fault: drop_frame {block, frame}, swap_frames {block}, corrupt_sample
    /// {block}, bad_frames {block}, interlock {at_s}, serial_garbage {at_s, port: ldv|amp},
    /// serial_silent {at_s, port}, mute {at_s}, vanish {at_s}.
    #[arg(long)]
    pub inject: Vec<String>,
    /// Rebuild the truth ROM even if cached.
    #[arg(long)]
    pub rebuild: bool,
    /// No progress display while building the ROM.
    #[arg(long)]
    pub quiet: bool,
}

/// The link faults `--inject` takes, with their fields, for error messages.
const LINK_KINDS: &str = "drop_frame {block, frame}, swap_frames {block}, corrupt_sample \
     {block}, bad_frames {block}, interlock {at_s}, serial_garbage {at_s, port: ldv|amp}, \
     serial_silent {at_s, port}, mute {at_s}, vanish {at_s}";

/// One `--inject` value: a link fault or a fault of the simulated rig (checked as `rigtwin
/// run --inject` checks it). An error names the kinds, or what is wrong with a known kind.
fn parse_inject(s: &str, beam_length_m: f64) -> anyhow::Result<Inject> {
    let all = || {
        format!(
            "the simulated rig's {}; link faults: {LINK_KINDS}",
            super::run::INJECT_KINDS
        )
    };
    let value: serde_json::Value = serde_json::from_str(s)
        .map_err(|e| anyhow::anyhow!("--inject {s}: not JSON ({e}); {}", all()))?;
    let unknown_kind = |e: &serde_json::Error| e.to_string().starts_with("unknown variant");
    match serde_json::from_value::<LinkFault>(value.clone()) {
        Ok(f) => Ok(Inject::Link(f)),
        Err(e) if !unknown_kind(&e) => {
            bail!("--inject {s}: not a fault description: {e}; {}", all())
        }
        Err(_) => match serde_json::from_value::<InjectedFault>(value) {
            Ok(_) => Ok(Inject::Rig(super::run::parse_inject(s, beam_length_m)?)),
            Err(e) if !unknown_kind(&e) => {
                bail!("--inject {s}: not a fault description: {e}; {}", all())
            }
            Err(_) => bail!("--inject {s}: unknown kind; {}", all()),
        },
    }
}

pub(crate) fn run(a: FirmwareSimArgs) -> anyhow::Result<()> {
    let cfg = match &a.config {
        Some(p) => RigConfig::from_path(p)?,
        None => RigConfig::default_rig(),
    };
    let inject: Vec<Inject> = a
        .inject
        .iter()
        .map(|s| parse_inject(s, cfg.rig.beam_length))
        .collect::<anyhow::Result<_>>()?;
    if let Some(c) = a.clearance {
        crate::plan::check_clearance(c)
            .map_err(|expected| anyhow::anyhow!("--clearance {c}: expected {expected}"))?;
    }
    let mut truth_cfg = cfg.clone();
    truth_cfg.reduction = crate::config::ReductionSpec {
        cutoff_ratio: Some(cfg.truth.cutoff_ratio),
        cutoff_hz: None,
        modes: None,
        contact_nodes: None,
    };
    let (truth, _, _) = super::models::cached_rom(&truth_cfg, a.rebuild, a.quiet)?;
    let spec = SimRigSpec::from_config(&cfg);
    let clearance_m = a.clearance.map_or(cfg.contact.clearance, |c| {
        crate::plan::per_l_to_metres(c, cfg.rig.beam_length)
    });
    let rig = SimRig::new(&truth, &spec, clearance_m).context("simulated rig")?;
    let opts = FirmwareOptions {
        listen: a.can_listen,
        pace: match a.pace {
            PaceArg::Realtime => Pace::Realtime,
            PaceArg::Virtual => Pace::Virtual,
        },
        heartbeat_period: HEARTBEAT_PERIOD,
        heartbeat_timeout: HEARTBEAT_TIMEOUT,
        ramp_down_s: cfg.safety.ramp_down_s,
        once: a.once,
        inject,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async {
        let mut fw = FirmwareSim::bind(
            rig,
            opts,
            spec.shaker.amplifier_gain,
            spec.shaker.amplifier_limit_v,
        )
        .await?;
        let line = serde_json::json!({ "firmware_sim": fw.endpoints() });
        println!("{line}");
        std::io::stdout().flush()?;
        fw.run(|r| {
            println!("{}", serde_json::json!({ "session_end": r }));
            let _ = std::io::stdout().flush();
        })
        .await?;
        Ok(())
    })
}
