//! `piezo loop`: the closed-loop figures of the thesis loop (sec. 4.1.2), measured on the
//! discrete loop of model-core's compensator and plant at the chosen rate and gain
//! ([`host_tests::sim::analysis`]).
use clap::Args;
use host_tests::sim::analysis::{LoopSetup, loop_figures};
use model_core::params;

/// Arguments of `piezo loop`.
#[derive(Args, Debug)]
pub struct LoopArgs {
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Loop rate, Hz (10000..200000).
    #[arg(long, default_value_t = params::SAMPLE_RATE_HZ, allow_negative_numbers = true)]
    pub rate: f64,
    /// Compensator gain Kc (0..1e6].
    #[arg(long, default_value_t = params::LAG_KC, allow_negative_numbers = true)]
    pub kc: f64,
}

fn fmt(v: Option<f64>, unit: &str) -> String {
    v.map_or_else(|| "n/a".to_string(), |x| format!("{x:.2} {unit}"))
}

/// Run `piezo loop`.
pub fn run(a: &LoopArgs) -> anyhow::Result<()> {
    if !(a.rate.is_finite() && a.rate > 0.0) {
        anyhow::bail!("--rate must be a positive number of Hz, got {}", a.rate);
    }
    let setup = LoopSetup::thesis(a.rate, a.kc);
    setup
        .validate()
        .map_err(|e| anyhow::anyhow!("invalid loop (--rate {} --kc {}): {e}", a.rate, a.kc))?;
    let f = loop_figures(&setup).map_err(|e| anyhow::anyhow!("{e}"))?;
    if a.json {
        println!("{}", serde_json::to_string(&f)?);
        return Ok(());
    }
    println!("Thesis loop at {:.0} Hz, Kc = {}", a.rate, a.kc);
    println!(
        "{:<26}{:>16}{:>16}{:>16}",
        "figure", "measured", "recomputed", "thesis"
    );
    let rows = [
        (
            "gain margin",
            fmt(f.gain_margin_db, "dB"),
            params::RECOMPUTED_GAIN_MARGIN_DB,
            params::THESIS_GAIN_MARGIN_DB,
            "dB",
        ),
        (
            "phase margin",
            fmt(f.phase_margin_deg, "deg"),
            params::RECOMPUTED_PHASE_MARGIN_DEG,
            params::THESIS_PHASE_MARGIN_DEG,
            "deg",
        ),
        (
            "gain crossover",
            fmt(f.crossover_rad_s, "rad/s"),
            params::RECOMPUTED_CROSSOVER_RAD_S,
            3300.0,
            "rad/s",
        ),
        (
            "closed-loop -3 dB",
            fmt(f.bandwidth_hz, "Hz"),
            params::RECOMPUTED_BANDWIDTH_HZ,
            950.0,
            "Hz",
        ),
    ];
    for (name, m, r, t, unit) in rows {
        println!(
            "{name:<26}{m:>16}{:>16}{:>16}",
            format!("{r} {unit}"),
            format!("{t} {unit}")
        );
    }
    println!(
        "{:<26}{:>16}",
        "1 V step overshoot",
        fmt(f.step_overshoot_pct, "%")
    );
    println!(
        "{:<26}{:>16}",
        "settling to 2 %",
        fmt(f.settling_2pct_ms, "ms")
    );
    if f.bandwidth_hz.is_none() {
        println!("the closed loop is unstable at this gain: no bandwidth or step response");
    }
    Ok(())
}
