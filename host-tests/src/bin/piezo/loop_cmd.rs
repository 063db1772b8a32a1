//! `piezo loop`: the closed-loop figures of the thesis loop (sec. 4.1.2), measured on the
//! discrete loop of model-core's compensator and plant at the chosen rate and gain
//! ([`host_tests::sim::analysis`]).
use clap::Args;
use host_tests::io::checks;
use host_tests::sim::analysis::{CROSSOVER_MIN_RAD_S, LoopSetup, loop_figures, open_loop_response};
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
    /// Compensator gain Kc (0..1e6]; the figures exist from about Kc = 400 (below, the gain
    /// crossover falls under the measured 100 rad/s and the verb says so).
    #[arg(long, default_value_t = params::LAG_KC, allow_negative_numbers = true)]
    pub kc: f64,
}

fn fmt(v: Option<f64>, unit: &str) -> String {
    v.map_or_else(|| "n/a".to_string(), |x| format!("{x:.2} {unit}"))
}

/// Run `piezo loop`.
pub fn run(a: &LoopArgs) -> anyhow::Result<()> {
    checks::within(
        "--rate",
        a.rate,
        params::MIN_SAMPLE_RATE_HZ,
        params::MAX_SAMPLE_RATE_HZ,
        "Hz",
    )?;
    if !(a.kc.is_finite() && a.kc > 0.0 && a.kc <= params::LAG_KC_MAX) {
        anyhow::bail!(
            "--kc must be within (0, {}] (got {})",
            params::LAG_KC_MAX,
            a.kc
        );
    }
    let setup = LoopSetup::thesis(a.rate, a.kc);
    setup
        .validate()
        .map_err(|e| anyhow::anyhow!("invalid loop (--rate {} --kc {}): {e}", a.rate, a.kc))?;
    let f = loop_figures(&setup).map_err(|e| anyhow::anyhow!("{e}"))?;
    // No crossover in the measured band: no figure at all, which is an answer only as an error.
    if f.crossover_rad_s.is_none() {
        let low = open_loop_response(&setup, CROSSOVER_MIN_RAD_S, 0.2, 5.0).norm() < 1.0;
        anyhow::bail!(
            "no gain crossover between {CROSSOVER_MIN_RAD_S} rad/s and a quarter of Nyquist at --kc {}: \
             the loop gain is {} 1 over the whole measured band, so no figure can be measured \
             (the crossover moves with Kc: about 0.31 rad/s per unit of Kc; choose --kc from about 400)",
            a.kc,
            if low { "below" } else { "above" }
        );
    }
    for (name, v) in [
        ("gain margin", f.gain_margin_db),
        ("phase margin", f.phase_margin_deg),
        ("gain crossover", f.crossover_rad_s),
        ("closed-loop bandwidth", f.bandwidth_hz),
        ("step overshoot", f.step_overshoot_pct),
        ("settling time", f.settling_2pct_ms),
    ] {
        if let Some(v) = v {
            checks::finite(name, v)?;
        }
    }
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
