//! The instruction budget: instructions per call of the whole control step and of each block,
//! counted on QEMU with `-icount shift=0` by SysTick (1 tick = 40 instructions; see the lib).
//!
//! Method: a closed loop (thesis controller on the linear plant, 100 Hz triangle reference,
//! sensor through the ADC codes) is run for a warm-up, then [`N`] samples of every block's
//! inputs are recorded. Each block is then timed over the recorded inputs in a loop of `N`
//! calls, starting from the state it had at the start of the recording, so it takes the same
//! branches as in the loop. An empty loop over the same inputs (the `overhead` line) is
//! subtracted by the host. `black_box` keeps inputs and outputs from being folded away.
//!
//! Every block is called through an `#[inline(never)]` wrapper, as the interrupt calls the
//! step: coefficients and state are loaded from memory on every call instead of staying in
//! registers across the timing loop, and the call and return are counted (a few
//! instructions), so the figures are what one interrupt pays, not a loop's best case.
//!
//! Output: `CPU <part>`, `CAL <ticks> <nops>` (a block of known length, to check the tick
//! size), `BENCH <name> <ticks> <calls>` per block, `STACK controller_step <bytes>` (stack
//! the step needs, by painting), `DONE 0`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod image {
    use core::hint::black_box;
    use model_core::closed_loop::{LinearStage, StageModel};
    use model_core::codes::{AdcCode, DacCode};
    use model_core::controller::{Controller, ControllerState, Mode, Sample};
    use model_core::controller::{ControllerConfig, ReferenceSource};
    use model_core::hysteresis::{HysteresisMemory, HysteresisTable};
    use model_core::lag::LagConfig;
    use model_core::lag::{LagCompensator, LagState};
    use model_core::learning;
    use model_core::limits::{Flags, OutputLimits};
    use model_core::plant::LinearPlantConfig;
    use model_core::plant::{LinearPlant, PlantState};
    use model_core::prefilter::PreFilterMode;
    use model_core::prefilter::{PreFilter, PreFilterConfig, PreFilterState};
    use model_core::reference::{ReferenceConfig, ReferenceGenerator, ReferenceState, Shape};
    use model_core::scenarios::{self, Scenario, scenario_controller};
    use model_core::stage::{Stage, StageConfig, StageState};
    use piezo_qemu::{EXIT_FAIL, EXIT_PASS, InstructionCounter, StackProbe, cpu_part, exit};

    /// Calls per timed loop.
    const N: usize = 1000;
    /// Samples run before recording.
    const WARM_UP: u32 = 2000;
    /// Length of the calibration block, instructions.
    const CAL_NOPS: u32 = 4000;

    struct Recording {
        adc: [AdcCode; N],
        error_v: [f32; N],
        raw_v: [f32; N],
        last_v: [f32; N],
        command_v: [f32; N],
        measured_v: [f32; N],
    }

    #[inline(never)]
    fn controller_step(c: &Controller, s: &mut ControllerState, adc: AdcCode) -> Sample {
        c.step(s, adc)
    }

    /// The interrupt's learning path (issue #14): the generator's index, the table's
    /// correction read and added, the step, the error recorded.
    #[inline(never)]
    fn controller_step_learning(
        c: &Controller,
        s: &mut ControllerState,
        adc: AdcCode,
        table: &[f32],
        error_v: &mut [f32],
    ) -> Sample {
        let index = c.reference_index(s);
        let sample = c.step_with_correction(s, adc, learning::correction(table, index));
        learning::record(error_v, index, &sample);
        sample
    }

    #[inline(never)]
    fn lag_update(c: &LagCompensator, s: &mut LagState, e: f32) -> (f32, Flags) {
        c.update_flags(s, e)
    }

    #[inline(never)]
    fn limits_apply(l: &OutputLimits, last: f32, raw: f32) -> (f32, Flags) {
        l.apply(last, raw)
    }

    #[inline(never)]
    fn adc_to_volts(a: AdcCode) -> f32 {
        a.volts()
    }

    #[inline(never)]
    fn dac_from_volts(v: f32) -> DacCode {
        DacCode::from_volts(v)
    }

    #[inline(never)]
    fn plant_step(p: &LinearPlant, s: &mut PlantState, u: f32) -> f32 {
        p.step(s, u)
    }

    #[inline(never)]
    fn prefilter_step(p: &PreFilter, s: &mut PreFilterState, r: f32) -> f32 {
        p.step(s, r)
    }

    #[inline(never)]
    fn reference_next(g: &ReferenceGenerator, s: &mut ReferenceState) -> f32 {
        g.next(s)
    }

    #[inline(never)]
    fn stage_step(st: &Stage, s: &mut StageState, u: f32) -> f32 {
        st.step(s, u)
    }

    #[inline(never)]
    fn hysteresis_forward(t: &HysteresisTable, m: &mut HysteresisMemory, u: f32) -> f32 {
        t.forward(m, u)
    }

    #[inline(never)]
    fn hysteresis_inverse(t: &HysteresisTable, m: &mut HysteresisMemory, y: f32) -> f32 {
        t.inverse(m, y)
    }

    fn report(name: &str, ticks: u32) {
        defmt::println!("BENCH {=str} {=u32} {=u32}", name, ticks, N as u32);
    }

    #[inline(always)]
    fn time(counter: &InstructionCounter, mut f: impl FnMut(usize)) -> u32 {
        let t0 = counter.now();
        for i in 0..N {
            f(i);
        }
        let t1 = counter.now();
        InstructionCounter::elapsed(t0, t1)
    }

    #[cortex_m_rt::entry]
    fn main() -> ! {
        defmt::println!("CPU {=u32}", cpu_part());
        let Some(p) = cortex_m::Peripherals::take() else {
            exit(EXIT_FAIL)
        };
        let counter = InstructionCounter::new(p.SYST);

        let t0 = counter.now();
        // SAFETY: nothing but no-operations.
        unsafe { core::arch::asm!(".rept 4000", "nop", ".endr", options(nomem, nostack)) };
        let t1 = counter.now();
        defmt::println!(
            "CAL {=u32} {=u32}",
            InstructionCounter::elapsed(t0, t1),
            CAL_NOPS
        );

        // The loop recorded: the triangle from the on-board generator through the pre-filter
        // (the controller's default trajectory use), on the linear plant.
        let (Ok(controller), Ok(mut stage)) = (
            scenario_controller(Scenario::Triangle),
            LinearStage::thesis(),
        ) else {
            exit(EXIT_FAIL)
        };
        let mut st = ControllerState::new(&controller);
        st.set_mode(Mode::ClosedLoop);
        for _ in 0..WARM_UP {
            let s = controller.step(&mut st, AdcCode::from_volts(stage.output_v()));
            stage.step(s.dac.volts());
        }
        let st0 = st.clone();
        let stage0 = stage;
        // The compensator's own state is private to the controller: shadow it with a
        // compensator driven by the same errors from the same command.
        let mut lag_state = LagState::new(st.command_v());
        let lag_state0 = lag_state;
        let mut rec = Recording {
            adc: [AdcCode(0); N],
            error_v: [0.0; N],
            raw_v: [0.0; N],
            last_v: [0.0; N],
            command_v: [0.0; N],
            measured_v: [0.0; N],
        };
        for i in 0..N {
            let adc = AdcCode::from_volts(stage.output_v());
            let last = st.command_v();
            let s = controller.step(&mut st, adc);
            let e = s.reference_v - s.measured_v;
            controller.lag.update(&mut lag_state, e);
            stage.step(s.dac.volts());
            rec.adc[i] = adc;
            rec.error_v[i] = e;
            rec.last_v[i] = last;
            // The limits see the compensator's raw output; the command is a fair stand-in
            // with the same branches (inside the window, within the slew limit).
            rec.raw_v[i] = s.command_v;
            rec.command_v[i] = s.dac.volts();
            rec.measured_v[i] = s.measured_v;
        }

        let overhead = time(&counter, |i| {
            black_box(black_box(rec.adc[i]));
        });
        report("overhead", overhead);

        let mut s = st0.clone();
        let ticks = time(&counter, |i| {
            black_box(controller_step(&controller, &mut s, black_box(rec.adc[i])));
        });
        report("controller_step", ticks);

        // The same with the learning's read-and-add and record (one 100 Hz repeat: 500
        // samples at 50 kHz).
        let table = [0.001f32; 500];
        let mut error_v = [0.0f32; 500];
        let mut s = st0.clone();
        let ticks = time(&counter, |i| {
            black_box(controller_step_learning(
                &controller,
                &mut s,
                black_box(rec.adc[i]),
                black_box(&table),
                &mut error_v,
            ));
        });
        report("controller_step_learning", ticks);

        // Other configurations of the same function, each warmed up on the recorded codes
        // first (entering closed loop is a one-off cost, not counted).
        let base = Scenario::Triangle.config();
        let configs = [
            (
                "controller_step_hysteresis_ff",
                ControllerConfig {
                    hysteresis_ff: true,
                    ..base
                },
            ),
            (
                "controller_step_external_no_prefilter",
                ControllerConfig {
                    source: ReferenceSource::External,
                    prefilter: PreFilterConfig {
                        mode: PreFilterMode::Off,
                        ..base.prefilter
                    },
                    ..base
                },
            ),
        ];
        for (name, cfg) in configs {
            let Ok(c) = Controller::new(&cfg) else {
                exit(EXIT_FAIL)
            };
            let mut s = ControllerState::new(&c);
            s.set_mode(Mode::ClosedLoop);
            s.set_reference(scenarios::TRIANGLE_OFFSET_V as f32);
            for i in 0..N {
                controller_step(&c, &mut s, rec.adc[i]);
            }
            let ticks = time(&counter, |i| {
                black_box(controller_step(&c, &mut s, black_box(rec.adc[i])));
            });
            report(name, ticks);
        }

        let mut s = st0.clone();
        s.raise(model_core::controller::Faults::WATCHDOG);
        let ticks = time(&counter, |i| {
            black_box(controller_step(&controller, &mut s, black_box(rec.adc[i])));
        });
        report("controller_step_faulted", ticks);

        let mut ls = lag_state0;
        let ticks = time(&counter, |i| {
            black_box(lag_update(
                &controller.lag,
                &mut ls,
                black_box(rec.error_v[i]),
            ));
        });
        report("lag_update", ticks);

        let limits = controller.lag.limits;
        let ticks = time(&counter, |i| {
            black_box(limits_apply(
                &limits,
                black_box(rec.last_v[i]),
                black_box(rec.raw_v[i]),
            ));
        });
        report("limits_apply", ticks);

        let ticks = time(&counter, |i| {
            black_box(adc_to_volts(black_box(rec.adc[i])));
        });
        report("adc_to_volts", ticks);

        let ticks = time(&counter, |i| {
            black_box(dac_from_volts(black_box(rec.command_v[i])));
        });
        report("dac_from_volts", ticks);

        let mut stage = stage0;
        let ticks = time(&counter, |i| {
            black_box(plant_step(
                &stage.plant,
                &mut stage.state,
                black_box(rec.command_v[i]),
            ));
        });
        report("plant_step", ticks);

        let Ok(pf) = PreFilter::new(
            &LagConfig::default(),
            &LinearPlantConfig::default(),
            &PreFilterConfig::default(),
        ) else {
            exit(EXIT_FAIL)
        };
        let mut ps = pf.settled_state(rec.measured_v[0]);
        let ticks = time(&counter, |i| {
            black_box(prefilter_step(&pf, &mut ps, black_box(rec.measured_v[i])));
        });
        report("prefilter_step", ticks);

        for (name, shape) in [
            ("reference_sine", Shape::Sine),
            ("reference_triangle", Shape::Triangle),
        ] {
            let Ok(g) = ReferenceGenerator::new(
                &ReferenceConfig {
                    shape,
                    offset_v: scenarios::TRIANGLE_OFFSET_V,
                    amplitude_v: scenarios::TRIANGLE_AMPLITUDE_V,
                    freq_hz: scenarios::TRIANGLE_HZ,
                    ..ReferenceConfig::default()
                },
                pf.preview_samples(),
            ) else {
                exit(EXIT_FAIL)
            };
            let mut gs = g.start();
            let ticks = time(&counter, |_| {
                black_box(reference_next(&g, &mut gs));
            });
            report(name, ticks);
        }

        let Ok(full) = Stage::new(&StageConfig::thesis_full()) else {
            exit(EXIT_FAIL)
        };
        let mut ss = full.steady_state(rec.command_v[0]);
        let ticks = time(&counter, |i| {
            black_box(stage_step(&full, &mut ss, black_box(rec.command_v[i])));
        });
        report("stage_step", ticks);

        let table = HysteresisTable::thesis_default();
        let mut mem = HysteresisMemory::new();
        for i in 0..N {
            table.forward(&mut mem, rec.command_v[i]);
        }
        let mem0 = mem.clone();
        let ticks = time(&counter, |i| {
            black_box(hysteresis_forward(
                &table,
                &mut mem,
                black_box(rec.command_v[i]),
            ));
        });
        report("hysteresis_forward", ticks);

        let mut mem = mem0;
        let ticks = time(&counter, |i| {
            black_box(hysteresis_inverse(
                &table,
                &mut mem,
                black_box(rec.measured_v[i]),
            ));
        });
        report("hysteresis_inverse", ticks);

        // Stack of one control step (painted below this frame, measured after the calls).
        let mut s = st0.clone();
        let probe = StackProbe::paint();
        for i in 0..16 {
            black_box(controller_step(&controller, &mut s, black_box(rec.adc[i])));
        }
        defmt::println!("STACK controller_step {=u32}", probe.used_bytes());

        defmt::println!("DONE 0");
        exit(EXIT_PASS)
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("this image runs on QEMU: cargo run -p host-tests --bin piezo -- qemu bench");
}
