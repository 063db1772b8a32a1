//! The board's numbers, in one module (Stabilizer's `design_parameters.rs`): resistor
//! values, link and SPI rates, watchdog and supervisor timing, capture size and the limits the
//! command language enforces. Each says where it comes from; most are our assumptions for
//! the NUCLEO-H743ZI2 build (issue #5). The control loop's own numbers, from the thesis,
//! stay in `model_core::params`.

// ----- Capture and the command link. -----
/// Records the firmware's capture buffer holds: 1 s at 50 kHz. At 8 bytes a record
/// (`model_core::frame::RECORD_LEN`) that is 400 kB of the H743's 512 KiB AXI SRAM (our
/// assumption).
pub const CAPTURE_RECORDS: usize = 50_000;
/// Baud rate of the command and capture link over the ST-LINK virtual COM port (USART3);
/// the ST-LINK V3 bridges it to USB (our assumption).
pub const UART_BAUD: u32 = 921_600;
/// The command UART's transmit ring buffer, bytes: two upload frames' worth of line time
/// (our assumption).
pub const UART_TX_BYTES: usize = 2048;
/// The command UART's receive ring buffer, bytes: several command lines (our assumption).
pub const UART_RX_BYTES: usize = 256;

// ----- Clocks (`hw/board.rs` sets them up and checks them against embassy's at boot). -----
/// CPU clock, Hz (the DWT cycle counter counts at this rate).
pub const CPU_HZ: u32 = 400_000_000;
/// Clock of the general-purpose timers on APB1 (TIM2), Hz.
pub const TIMER_CLOCK_HZ: u32 = 200_000_000;

// ----- What a command may ask for. -----
/// Highest frequency of an on-board sine or triangle reference, Hz: twice the closed-loop
/// bandwidth of about 1 kHz (model card); our assumption.
pub const REF_MAX_FREQ_HZ: f64 = 2_000.0;
/// Lowest frequency of an on-board sine or triangle reference, Hz (our assumption).
pub const REF_MIN_FREQ_HZ: f64 = 0.001;
/// Lowest sensor monitor voltage a reference may ask for, volts (E-509 range 0..10 V, sec. 2.4).
pub const REF_MIN_V: f64 = 0.0;
/// Highest sensor monitor voltage a reference may ask for, volts (10 V = 12 um, sec. 2.4).
pub const REF_MAX_V: f64 = 10.0;
/// Shortest pre-filter time constant a command may set, seconds (our assumption).
pub const TAU_MIN_S: f64 = 1.0e-6;
/// Longest pre-filter time constant a command may set, seconds (our assumption).
pub const TAU_MAX_S: f64 = 0.1;

// ----- Watchdog, supervisor, heartbeat (issue 13 item 1: one consistent set). -----
// The chain, each link shorter than the next (checked at compile time below):
// a task checks in at least every TASK_CHECK_IN_S; the supervisor sees a complete round at its
// next call (SUPERVISOR_PERIOD_S later), so a healthy round is at most
// TASK_CHECK_IN_S + SUPERVISOR_PERIOD_S old, well under TASK_STALL_S; after TASK_STALL_S the
// interrupt raises WATCHDOG (ramps to safe) and the supervisor stops feeding; the IWDG bites
// IWDG_TIMEOUT_S after the last feed.
/// Independent watchdog (IWDG) timeout, seconds: the chip resets if the interrupt or the
/// tasks stop for this long (our assumption).
pub const IWDG_TIMEOUT_S: f64 = 0.1;
/// How often the supervisor task checks liveness and may feed the IWDG, seconds (our
/// assumption).
pub const SUPERVISOR_PERIOD_S: f64 = 0.01;
/// Longest interval between two check-ins of a healthy required task, seconds: the command
/// task's read timeout and the heartbeat task's tick (our assumption).
pub const TASK_CHECK_IN_S: f64 = 0.01;
/// The interrupt raises the watchdog fault (and ramps to safe) when the tasks have not
/// checked in for this long, seconds: well before the IWDG bites (our assumption).
pub const TASK_STALL_S: f64 = 0.05;
/// Heartbeat LED half period, seconds: the LED only; the heartbeat task checks in every
/// [`TASK_CHECK_IN_S`] and toggles the LED every [`HEARTBEAT_TICKS_PER_TOGGLE`] ticks.
pub const HEARTBEAT_HALF_PERIOD_S: f64 = 0.25;
/// Heartbeat ticks per LED toggle.
pub const HEARTBEAT_TICKS_PER_TOGGLE: u32 = (HEARTBEAT_HALF_PERIOD_S / TASK_CHECK_IN_S) as u32;
/// Time from the loop's start (TIM2 running) to the tasks' start at boot, seconds: the main
/// task waits this long before it closes the output switch and spawns the tasks (our
/// assumption).
pub const BOOT_LOOP_TO_TASKS_S: f64 = 0.01;

const _: () = {
    // A complete round is seen at most one check-in interval plus one supervisor period
    // after the fact (plus the boot delay once); it must stay below the stall limit with
    // margin for scheduling jitter (20 ms with the values above).
    assert!(
        TASK_CHECK_IN_S + SUPERVISOR_PERIOD_S + BOOT_LOOP_TO_TASKS_S + 0.02 <= TASK_STALL_S + 1e-9
    );
    // The interrupt's WATCHDOG fault (and the ramp to safe) comes before the IWDG reset.
    assert!(TASK_STALL_S + SUPERVISOR_PERIOD_S < IWDG_TIMEOUT_S);
    // A healthy supervisor feeds several times per IWDG window.
    assert!(SUPERVISOR_PERIOD_S * 4.0 <= IWDG_TIMEOUT_S);
    assert!(HEARTBEAT_TICKS_PER_TOGGLE >= 1);
};

// ----- Loop delay. -----
/// Samples of computational delay the board adds to the loop: the interrupt sends, first
/// thing, the code computed in the previous sample (`hw/control.rs`, issue 13 item 6), so a
/// reading acts on the amplifier one period later than in the thesis' identification loop,
/// whose 85 us (eq. 4.4) the plant model carries. The pre-filter's model of the loop delay
/// adds these samples ([`crate::settings::Settings::controller_config`]).
pub const COMPUTATIONAL_DELAY_SAMPLES: u32 = 1;

// ----- External DAC. -----
/// SPI clock of the external DAC, Hz (DAC8311 allows 50 MHz, AD5641 30 MHz; our choice leaves
/// margin for wiring): a 16-bit frame takes 1.3 us.
pub const DAC_SPI_HZ: u32 = 12_500_000;

// ----- ADC front end (our design; see the firmware README). -----
/// ADC front end (firmware README): series resistor from the sensor monitor to the buffer
/// input, ohms (our design).
pub const ADC_R_IN_OHM: f64 = 100.0e3;
/// ADC front end: resistor from VREF+ to the buffer input, ohms (E96; our design).
pub const ADC_R_REF_OHM: f64 = 32.4e3;
/// ADC front end: resistor from the buffer input to ground, ohms (E96; our design).
pub const ADC_R_GND_OHM: f64 = 48.7e3;
/// VREF+ of the NUCLEO-H743ZI2 (tied to VDDA, 3.3 V; UM2407).
pub const ADC_VREF_V: f64 = 3.3;
/// ADC front end: pull resistor from the input node (the BNC side of R1) to
/// [`ADC_PULL_RAIL_V`], ohms (issue 13 item 2; our design). With the sensor unplugged the
/// node would sit at 1.98 V through the network (a plausible reading); with this pull it
/// reads -2.5 V, below the controller's `SENSOR_VALID_MIN_V` (-0.5 V) by 2 V, and the pin
/// stays inside 0..VREF+. With the E-509 connected (a low-impedance op-amp output) it only
/// draws 30..76 uA from the monitor and does not change the scaling.
pub const ADC_R_PULL_OHM: f64 = 330.0e3;
/// ADC front end: the rail the pull resistor goes to, volts (the -15 V of the output stage's
/// supply; our design).
pub const ADC_PULL_RAIL_V: f64 = -15.0;

// ----- Calibration a `cal` command may set. -----
/// Largest gain correction a `cal` command may set (our assumption: +-10 %).
pub const CAL_MAX_GAIN_ERROR: f64 = 0.1;
/// Largest offset correction a `cal` command may set, volts (our assumption).
pub const CAL_MAX_OFFSET_V: f64 = 0.5;

// ----- `selftest` over a loopback cable (issue 13, bring-up; all our assumptions). -----
/// Levels the self-test steps through, volts at the amplifier input (open loop); with the
/// loopback cable the front end reads them back.
pub const SELFTEST_LEVELS_V: [f64; 3] = [1.0, 5.0, 9.0];
/// Samples captured per level from the step on; the second half gives the statistics, the
/// first the latency.
pub const SELFTEST_SAMPLES: u32 = 2000;
/// Largest gain error of the loopback (DAC stage -> front end) for a pass.
pub const SELFTEST_MAX_GAIN_ERROR: f64 = 0.01;
/// Largest offset of the loopback for a pass, volts.
pub const SELFTEST_MAX_OFFSET_V: f64 = 0.02;
/// Largest RMS noise of the read-back at a level for a pass, volts (the E-509's own noise is
/// 2.5 mV; the converters alone should be well under 1 mV).
pub const SELFTEST_MAX_NOISE_V: f64 = 1.0e-3;
/// Largest latency from the computed code to its read-back for a pass, samples (one sample
/// waiting for the fixed DAC instant, one to the next conversion, one of margin).
pub const SELFTEST_MAX_LATENCY_SAMPLES: u32 = 3;
/// Largest interrupt time for a pass, as a fraction of the period.
pub const SELFTEST_MAX_ISR_FRACTION: f64 = 0.5;
