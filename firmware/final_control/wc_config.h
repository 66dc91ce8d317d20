// wc_config.h: every constant of the final_control firmware in one place.
//
// GENERATED from protocol/spec.toml by `python -m wcdrive.protocol.spec --write`:
// edit the spec, not this file. tests/protocol/test_protocol.py fails when they differ.
#ifndef WC_CONFIG_H
#define WC_CONFIG_H

// ---- Serial link -----------------------------------------------------------
#define WC_BAUD 115200UL
#define WC_CMD_MAX_LEN 63          // longest command (bytes before its terminator)
#define WC_ERR_LINES_PER_TICK 3    // commands answered per 50 ms window (ERR, ACK/NAK, data); the rest are counted
#define WC_PROTOCOL_VERSION 4      // sent in the HELLO reply to hello:4: every line the board sends is framed
#define WC_PROTOCOL_VERSION_PLAIN 3 // sent in the HELLO reply to a plain hello: the board's lines stay unframed, as in v3
#define WC_FIRMWARE_VERSION "4.0.0" // final_control's version, sent in the HELLO reply
#define WC_SEQ_MAX 65535UL         // largest sequence number of a v3 frame
#define WC_NUMBER_MAX_DIGITS 24    // most digits of a number before its exponent (leading zeros count): ERR:number past it
#define WC_NUMBER_MAX_EXP_DIGITS 2 // most digits of a number's exponent: ERR:range past it
#define WC_TX_CREDIT_MAX 500       // output budget: bytes the board may queue at once, what one control period refills (the UART drains more than the refill, so the ring's bytes and the credit never add up to more than this and the 20 bytes of the 2 ms by which millis() may run ahead of the UART between two ticks: 520 of the ring's 1023)
#define WC_TX_CREDIT_BOOT 480      // output budget: the credit setup() starts with, after the BOOT line, which may still be in the TX ring (31 bytes at most: with the credit and the 2 ms, 531 of the ring's 1023; the first tick, 50 ms on, finds it sent)
#define WC_TX_CREDIT_PER_MS 10     // output budget: bytes added per millisecond between control ticks (the UART sends 10.7 a ms)
#define WC_TX_LINE_MAX 144         // bytes of the longest line the board sends, its v4 suffix and line end included (LineBuffer's buffer)
#define WC_LINE_COUNTER_WRAP 256   // a v4 board line's counter (#NN) counts the framed lines sent, modulo this

// ---- Timing ----------------------------------------------------------------
#define WC_CONTROL_PERIOD_MS 50UL  // control tick and feedback period
#define WC_WATCHDOG_MS 500UL       // default of watchdog_ms: no valid command for this long -> emergency stop
#define WC_PIVOT_TICKS 6           // pivot length in control ticks (300 ms nominal)
#define WC_NEUTRAL_TICKS 2         // control ticks a neutral (zero) command must stand, no motion command after it, before the board drives after a boot, a fault or e-stop reset, a watchdog stop or a PPM loss (ISO 7176-14, control signal at switch-on): 100 ms nominal
#define WC_INHIBIT_DEBOUNCE_TICKS 2 // control ticks an inhibit input must read its new level before it counts (100 ms; commercial controllers debounce 50 to 500 ms)
#define WC_INHIBIT_1_SPEED 0.0f    // inhibit input 1 (charger) engaged: the top wheel speed as a share of max_wheel; 0 inhibits driving (ISO 7176-14, inhibit while charging)
#define WC_INHIBIT_1_LATCH 1       // 1: inhibit input 1 stays engaged once engaged, until released and a reset
#define WC_INHIBIT_2_SPEED 0.3f    // inhibit input 2 (seat raised) engaged: the top wheel speed as a share of max_wheel (a speed cap)
#define WC_INHIBIT_2_LATCH 0       // 1: inhibit input 2 latches as input 1 may; 0: it follows its input
#define WC_NEUTRAL_FAULT_TICKS 100 // control ticks (5 s) of refused motion commands without a neutral one: EVT:DEFLECTED, a deflected control latched until neutral (the 5 s commercial controllers latch after)

// ---- Geometry and encoders (seed section 1.4.2) ----------------------------
#define WC_CPR 10000.0f            // counts per wheel revolution (2500 PPR x4)
#define WC_WHEELBASE 0.57f         // m
#define WC_WHEEL_RADIUS 0.1524f    // m
#define WC_TWO_PI 6.28318548f      // 2*pi rounded to binary32

// ---- Limits ----------------------------------------------------------------
#define WC_MAX_WHEEL_SPEED 17.59f  // rad/s, WHEEL range and CMDVEL wheel limit
#define WC_MAX_LINEAR 2.68f        // m/s, CMDVEL x range
#define WC_MAX_ANGULAR 9.4f        // rad/s, CMDVEL t range

// ---- Controller ------------------------------------------------------------
#define WC_ALPHA 0.8f              // IIR filter coefficient
#define WC_MAX_ACCEL 5.0f          // rad/s^2, normal setpoint ramp
#define WC_EMERGENCY_DECEL 15.0f   // rad/s^2, watchdog and PPM-loss ramp
#define WC_PID_OUT_MAX 100.0f      // PID output limit (percent of full duty)
#define WC_PWM_SCALE 2.55f         // percent -> 8-bit duty
#define WC_KP_R 7.0f
#define WC_KI_R 8.0f
#define WC_KD_R 0.15f
#define WC_KP_L 7.2f
#define WC_KI_L 8.5f
#define WC_KD_L 0.15f
#define WC_STILL_SPEED 0.05f       // rad/s: |filtered velocity| below this is "still"
#define WC_STILL_TICKS 3           // consecutive still ticks before the motors park

// ---- Pivot (caster swivel) -------------------------------------------------
#define WC_PIVOT_SPEED 2.0f        // rad/s per wheel, right +, left -
#define WC_PIVOT_THRESHOLD 0.1f    // m/s of travel on either side of zero
#define WC_PIVOT_START_SPEED 0.5f  // rad/s: the rotation starts once both wheels are slower

// ---- PPM -------------------------------------------------------------------
#define WC_PPM_CHANNELS 8
#define WC_PPM_NEUTRAL 1500
#define WC_PPM_SPAN 500            // us from neutral to full stick
#define WC_PPM_DEADBAND 10         // us around neutral read as neutral
#define WC_PPM_VALID_MIN 900       // a channel outside [MIN, MAX] means signal lost
#define WC_PPM_VALID_MAX 2100
#define WC_PPM_MAX_WHEEL 5.0f      // rad/s at full stick
#define WC_PPM_FWD_CHANNEL 1       // zero-based: channel 2 is forward/back
#define WC_PPM_TURN_CHANNEL 3      // zero-based: channel 4 is turn (stick right = turn right)

// ---- Pins (Arduino Mega 2560 numbering) ------------------------------------
#define WC_PIN_ENC_L_A 2           // PE4, INT4
#define WC_PIN_ENC_L_B 3           // PE5, INT5
#define WC_PIN_ENC_R_A 18          // PD3, INT3
#define WC_PIN_ENC_R_B 19          // PD2, INT2
#define WC_PIN_PWM_L 9             // PH6, OC2B
#define WC_PIN_PWM_R 10            // PB4, OC2A
#define WC_PIN_DIR_L 8             // PH5
#define WC_PIN_DIR_R 11            // PB5
#define WC_PIN_RELAY 7             // PH4, powers the SmartDriveDuo
#define WC_PIN_INHIBIT_1 24        // PA2, inhibit input 1 (the charger): INPUT_PULLUP, active LOW (a contact to ground)
#define WC_PIN_INHIBIT_2 25        // PA3, inhibit input 2 (the seat raised): INPUT_PULLUP, active LOW
#define WC_PIN_BRAKE 22            // PA0, the parking brake: HIGH releases it; LOW, or an input (at reset: the driver's pull-down), engages it
#define WC_PIN_PUSH 26             // PA4, the parking brake's manual-release lever switch (push mode): INPUT_PULLUP, active LOW (the lever pulled, the brake released by hand)
#define WC_PIN_BRAKE_STATUS 23     // PA1, the brake driver's status output (a smart power switch's open-drain diagnostic): INPUT_PULLUP; LOW is a coil fault, an open load while the brake is engaged (the switch off) or an overload while it is released (on)

// ---- Fault detection (EVT:FAULT; docs/safety.md) ---------------------------
#define WC_FAULT_STALL_PWM 26      // duty (10 %) at or above which a turning wheel must show encoder counts (one that stood: FAULT_STALL_PWM_STANDING)
#define WC_FAULT_STALL_PWM_STANDING 42 // duty (16 %) at or above which a wheel that stood beside a standing partner (both slower than FAULT_STANDING_SPEED when the PID last ran) must show encoder counts: the driver's 13 A current limit at a standstill, the motor's full torque, at which a healthy chair starts its wheels within its rated grade (the grade's definition); on a grade a standing wheel at a lower duty may not turn
#define WC_FAULT_STANDING_SPEED 0.3f // rad/s: a wheel and its partner both slower than this when the PID last ran stand (FAULT_STALL_PWM_STANDING); a chair that still moves, however slowly, has a wheel turning
#define WC_FAULT_STALL_TICKS 2     // ticks driven at FAULT_STALL_PWM without a count: stalled or cut encoder
#define WC_FAULT_STALL_TICKS_TURNING 4 // ...by a wheel whose last motion ran against its setpoint: one turning round stands while its duty builds to break it away
#define WC_FAULT_STALL_TICKS_LOADED 6 // ...by a wheel below FAULT_STALL_PWM_STANDING that stands by its current on a loaded chair (its motor drawing STANDING_DRAW_SHARE of a stand's current, its partner short of its setpoint: standsByCurrent): a wheel standing under a load at the edge of moving creeps a count every tick or two (the envelope's drive 176: 2 count-less ticks at the most), a locked wheel or a held cut encoder's counts none
#define WC_FAULT_REVERSE_SPEED 1.0f // rad/s: setpoint and measured speed both beyond it, opposite signs
#define WC_FAULT_REVERSE_TICKS 3   // ticks of measured speed against the setpoint: reversed encoder
#define WC_FAULT_REVERSE_APPROACH 0.1f // rad/s: a wheel against its setpoint that came this much closer to it since the PID last ran is slowing toward it (lagging a reversal of its setpoint): not counted
#define WC_FAULT_RUNAWAY_PWM 26    // duty (10 %) at or above which a wheel driven against its measured motion is braking it: a braked wheel does not keep speeding up unless something pushes it, or its encoder counts against the motion
#define WC_FAULT_RUNAWAY_GAIN 0.07f // rad/s: a wheel braked at FAULT_RUNAWAY_PWM, FAULT_REVERSE_SPEED or more beyond its setpoint, that measures at least this much faster than the speed the PID last ran on, is running away: counted
#define WC_FAULT_RUNAWAY_TICKS 5   // net ticks running away (driving, each other tick counts one down, to 0; holding, to 0): reversed encoder (the positive feedback of one whose reading flipped sign with its setpoint)
#define WC_FAULT_EFFORT_PWM 20     // duty rise (8 %) toward a steady setpoint without any gain in speed: the motor does not respond
#define WC_FAULT_EFFORT_SHORTFALL 0.8f // ...while the wheel turns slower than this fraction of its setpoint
#define WC_FAULT_EFFORT_SHORTFALL_MOTOR 0.95f // ...while the wheel turns slower than this fraction of its setpoint (the motor rule; a dead motor's wheel dragged at speed keeps most of its setpoint, a healthy one at steady speed keeps more: 92 % at 1 m/s on the level)
#define WC_FAULT_EFFORT_LEAD 0.45f // rad/s: ...while turning its way no faster than this beyond the other wheel (or beyond standing, when the other turns against it): a dead motor's wheel is only dragged, and trails the wheel that drags it
#define WC_FAULT_EFFORT_TICKS 4    // consecutive ticks of that effort without progress: the motor fault
#define WC_FAULT_EFFORT_OVERRUN 0.5f // rad/s: ...nor while the other wheel turns this much beyond its setpoint its way: the chair does not follow the command (momentum, a slope), and the wheel's effort goes into it
#define WC_FAULT_EFFORT_EMF 14.5f  // duty per rad/s of wheel speed that the motor's back-EMF takes (255 / MAX_WHEEL_SPEED, rounded): a wheel's duty less this times its speed is its effort, the share of the duty that drives current
#define WC_FAULT_EFFORT_MAX 41.0f  // the largest effort that counts (duty): what drives the driver's 13 A current limit through the 0.3 ohm armature from 24 V; a wheel asking more gets no more torque, so two wheels at their current limit have equal efforts, however far one is behind
#define WC_FAULT_EFFORT_LEAD_PWM 10.0f // ...and the motor fault only while the wheel's effort leads the other wheel's (toward its own setpoint) by this much duty: one motor doing nothing while its partner carries the chair, not the chair's load on both (a grade, a kerb, a ramp's edge)
#define WC_FAULT_EFFORT_LAG 1.0f   // rad/s: ...or, both efforts at FAULT_EFFORT_MAX, while the wheel falls this much farther short of its setpoint than the other of its own: equal torques do not turn a chair, a dead motor's partner at its current limit does
#define WC_FAULT_ILLEGAL_PER_TICK 4 // illegal transitions in one tick: implausible encoder
#define WC_STORM_EDGES 80          // edges of one encoder in one Timer0 period (1.024 ms) that mask it: 78,000 edges/s, > 2.5x top speed, above the 70,000 every edge is counted at
#define WC_STORM_COMPARE 128       // OCR0A: the Timer0 count at which each storm window starts
#define WC_HW_WATCHDOG 3           // AVR watchdog period (avr/wdt.h WDTO_120MS): a loop() pass that hangs longer resets the board
#define WC_BRAKE_DONE_SPEED 0.3f   // rad/s: an emergency stop keeps braking until both wheels are slower

// ---- The parking brake, with brake_fitted 1 (docs/safety.md, "The parking brake") ---
#define WC_BRAKE_FITTED 0          // default of brake_fitted: 0, no brake (PIN_BRAKE still follows the PID: LOW whenever parked or faulted); 1, the firmware engages it at rest and unpowers the motors, releases it under the hold, and watches its coil
#define WC_BRAKE_ACTIVE_TICKS 1    // control ticks parked, the hold braking, before the brake engages: 1, at the first parked tick (the active braking is the ramp that parks the chair below BRAKE_DONE_SPEED; each tick more lets the hold roll the chair back a few mm on a grade before the brake takes it: 5.4 mm with 2 on a 1:12 climb, 10.9 mm with 6)
#define WC_BRAKE_ENGAGE_TICKS 2    // control ticks from PIN_BRAKE LOW to the motors unpowered while parked (the brake's engage time; 100 ms against the plant's 50 ms)
#define WC_BRAKE_PRELOAD_TICKS 1   // control ticks the hold drives, the brake still engaged, before PIN_BRAKE goes HIGH: the hold's current is up before the brake lets go
#define WC_BRAKE_RELEASE_TICKS 2   // control ticks from PIN_BRAKE HIGH to driving, the hold on meanwhile (the brake's release time; 100 ms against the plant's 50 ms)
#define WC_PUSH_SPEED 4.0f         // rad/s (0.61 m/s): in push mode the motors freewheel (each at the duty its back-EMF takes, FAULT_EFFORT_EMF a rad/s: no current) while both wheels are slower; a wheel pushed faster is at duty 0, its motor shorted, braking it
#define WC_BRAKE_STATUS_TICKS 2    // control ticks in a row PIN_BRAKE_STATUS must read LOW, PIN_BRAKE at one level throughout (a change starts the count again), before a coil fault latches (EVT:FAULT,BRAKE_OPEN with the brake engaged, BRAKE_SHORT released)

// ---- The motors' heat, estimated (docs/safety.md, "Motor heat") ------------
#define WC_THERMAL_AMBIENT 25.0f   // deg C: each winding's estimate at reset, and what it cools toward (the board measures no temperature: a warm room assumed; in hotter air the winding runs hotter than the estimate by the difference, and a reset forgets a hot motor)
#define WC_THERMAL_RESISTANCE 2.5f // K/W, winding to ambient (the motor's figure; assumed, as the plant's)
#define WC_THERMAL_CAPACITY 360.0f // J/K, the winding's thermal mass (assumed, as the plant's: a time constant of 900 s)
#define WC_THERMAL_EMF 14.0f       // duty per rad/s of wheel speed that the motor's back-EMF takes, for the heat estimate: the motor's own constant (Ke G x 255 / 24 V; the plant's, 14.0), not FAULT_EFFORT_EMF's rounded 14.5, which reads a cruising motor's current 16 % low
#define WC_THERMAL_LOSS 0.029527f  // W of copper loss per duty squared of effort (duty less THERMAL_EMF a rad/s, within FAULT_EFFORT_MAX): (24 V / 255)^2 / 0.3 ohm; the estimate does not read the current senses (it came before them), so it estimates the current from what it commands and what the encoders measure
#define WC_THERMAL_ROLLBACK_TEMP 110.0f // deg C (estimated): above it the rollback lowers each motor's current limit (the driving effort the PID may ask, from FAULT_EFFORT_MAX toward THERMAL_EFFORT_MIN) and the top speed (toward THERMAL_SHARE_MIN of max_wheel), linearly to THERMAL_CUTOFF_TEMP; EVT:THERMAL,1
#define WC_THERMAL_HYSTERESIS 5.0f // K: the rollback's end (EVT:THERMAL,0) waits until both estimates are this far below THERMAL_ROLLBACK_TEMP
#define WC_THERMAL_CUTOFF_TEMP 125.0f // deg C (estimated): EVT:FAULT,OVERHEAT_L/R; the rollback is full here. In a 20 to 30 deg C room the winding is then at 120 to 130 deg C, within its class B rating (130)
#define WC_THERMAL_EFFORT_MIN 25.0f // duty: the driving effort at full rollback (7.8 A); braking is never limited. The estimate settles near 115.6 deg C where the limit it sets holds it, short of the cut-off
#define WC_THERMAL_SHARE_MIN 0.5f  // of max_wheel: the top speed at full rollback, the curvature kept

// ---- The supply, measured, and the low battery (docs/safety.md, "The battery") ---
#define WC_PIN_SUPPLY 0            // analog input (A0, PF0, ADC0) of the supply sense: the battery through a SUPPLY_DIVIDER divider (100 kohm over 20 kohm), AVcc (5 V) the reference; one conversion a tick, started by the tick and read by the next
#define WC_SUPPLY_DIVIDER 6.0f     // battery volts per volt at PIN_SUPPLY (30 V full scale: a 24 V lead-acid battery charges to 28.8 V)
#define WC_SUPPLY_VOLTS_PER_COUNT 0.029296875f // battery volts per ADC count: 5 V x SUPPLY_DIVIDER / 1024 (the ATmega2560 datasheet's ADC = Vin x 1024 / Vref)
#define WC_SUPPLY_FILTER 0.05f     // the measured supply's low-pass filter, per tick (a time constant of 1 s): the sag of a start or a kerb passes, a climb's stays
#define WC_BATTERY_LOW_V 23.0f     // V (filtered, under load): below it the low-battery rollback lowers the top speed, linearly to BATTERY_SHARE_MIN of max_wheel at BATTERY_CUTOFF_V (71 % at 21 V); EVT:BATTERY,1. A full battery (25.6 V at rest, 24.3 V at both motors' current limit through its 0.05 ohm) never reaches it; an empty one (23.6 V at rest) does under a heavy load (assumed figures of two 12 V AGM blocks in series: the plant's)
#define WC_BATTERY_HYSTERESIS 0.5f // V: the rollback's end (EVT:BATTERY,0) waits until the filtered supply is this far above BATTERY_LOW_V
#define WC_BATTERY_CUTOFF_V 19.5f  // V (filtered): EVT:FAULT,UNDERVOLT, the chair stops along the fault ramp and parks (held, or braked with a brake fitted): a lead-acid battery's end of discharge under a heavy load (1.63 V a cell; assumed), below the 21 V of a low battery the chair must still drive on (tests/sim/test_grade_false_alarms.py); a supply sense that reads nothing (a cut wire, A0 at ground) faults too
#define WC_BATTERY_SHARE_MIN 0.5f  // of max_wheel: the top speed at BATTERY_CUTOFF_V, the curvature kept

// ---- The motors' currents, measured, and the stall timeout (docs/safety.md, "Stall timeout") ---
#define WC_PIN_CURRENT_L 1         // analog input (A1, PF1, ADC1) of the left motor's current sense: a bidirectional Hall sensor in the motor lead (Allegro ACS758LCB-050B: 40 mV/A, VCC/2 at 0 A, ratiometric to the 5 V AVcc the ADC takes for its reference); converted after the tick's start, by the ADC interrupt, and read by the next tick
#define WC_PIN_CURRENT_R 2         // analog input (A2, PF2, ADC2) of the right motor's current sense (as PIN_CURRENT_L)
#define WC_CURRENT_ZERO_COUNTS 512 // the ADC count of 0 A: the sensor's VCC/2
#define WC_CURRENT_AMPS_PER_COUNT 0.1220703125f // A per ADC count from CURRENT_ZERO_COUNTS: 5 V / 1024 / 0.040 V/A; either way round (the sign is the motor's direction)
#define WC_STALL_CURRENT 11.0f     // A: a motor drawing this much or more, its wheel standing beside a standing partner and driven toward its setpoint at FAULT_STALL_PWM_STANDING or more, is held at its current limit (the driver's 13 A: the PID's largest effort, FAULT_EFFORT_MAX, draws 12.9 A into a standing motor): not an encoder fault (ENC_STALL, DRIVER), which is a wheel driven without counts while its motor draws less (a cut encoder's wheel spins up, its back-EMF takes the current off), but the stall timeout's
#define WC_STALL_CREEP_COUNTS 2    // encoder counts a tick (0.025 rad/s, 4 mm/s) either way that a wheel held at its current limit, and its partner, may creep (a tyre against a wall gives a little): more from the partner is a chair that moves (crawling up a grade at its limit: 14 counts a tick at 0.18 rad/s), beside which a count-less wheel is a stalled encoder
#define WC_STALL_HELD_OUTPUT 16.5f // percent of full duty (duty 42, FAULT_STALL_PWM_STANDING: the driver's current limit into a standing motor, its full torque): the PID's bound either way for a wheel held at its current limit (STALL_CURRENT), its integral back-calculated to it: no harder than the motor's full torque at a standstill. Its current then bounds how fast it turns: a duty of 42 less the 35 that drive 11 A through the armature leaves 7 for back-EMF, 0.5 rad/s (0.076 m/s); a wheel turning faster (a cut encoder's) draws less and is an encoder fault
#define WC_STALL_TIMEOUT 15.0f     // s: the default of stall_timeout, a runtime parameter saved in EEPROM: a wheel held at its current limit (STALL_CURRENT) this long without a break stops the chair (EVT:STALL_TIMEOUT, the emergency ramp and the hold; motion refused until a stop, then a neutral command). Dynamic Controls DX's default, in its 5 to 50 s
#define WC_STALL_TIMEOUT_MIN 1.0f  // s: stall_timeout in [STALL_TIMEOUT_MIN, STALL_TIMEOUT_MAX]
#define WC_STALL_TIMEOUT_MAX 60.0f
#define WC_MOTOR_AMPS_PER_DUTY 0.3137f // A a duty of effort (FAULT_EFFORT_EMF's units: the duty less what the back-EMF takes) drives through the armature: 24 V / 255 / 0.3 ohm (the plant's armature_resistance, assumed; a real chair's motor is measured and the figure set here)
#define WC_STANDING_DRAW_SHARE 0.75f // of the current its duty drives through a standing armature (MOTOR_AMPS_PER_DUTY a duty): a wheel driven toward its setpoint whose motor draws this share or more the way it is driven stands by its current, its back-EMF a quarter of its duty or less (at duty 41 and 24 V, 0.73 rad/s, 11 cm/s at most), and, while its partner too falls short of its setpoint (FAULT_EFFORT_SHORTFALL: the chair is loaded), stalls after FAULT_STALL_TICKS_LOADED count-less ticks below FAULT_STALL_PWM_STANDING: a wheel standing under a load below the motor's full torque (across a grade) creeps, a stalled encoder does not; a cut encoder's wheel that turns draws less, its back-EMF takes the current off
#define WC_MOTOR_DRAW_MIN 1.0f     // A: a motor whose wheel turns its setpoint's way (FAULT_STANDING_SPEED or more, counting this tick), drawing this much or more the way its effort calls for (driving toward its setpoint, or braking) and MOTOR_DRAW_SHARE of what that effort drives through the armature (MOTOR_AMPS_PER_DUTY a duty), works: effort without progress is then the wheel's load, never MOTOR_L/R (a dead motor or driver draws nothing; one shorted to a brake draws against its effort)
#define WC_MOTOR_SILENT_CURRENT 3.0f // A: a motor drawing less than MOTOR_DRAW_MIN either way while its duty and its wheel's measured speed call for this much or more, either way, is silent: an open winding or a dead driver. When the motor rule would blame its partner, whose motor draws what its effort calls for, the silent one is named instead (MOTOR_L/R): a dead wheel carried down a grade while its partner brakes at the limit
#define WC_MOTOR_DRAW_SHARE 0.5f   // of the current a wheel's effort (its duty less FAULT_EFFORT_EMF a rad/s of its measured speed) drives through the armature: a working motor draws about all of it (the reading lags the duty a tick); a dead one nothing. The effort is taken within FAULT_EFFORT_MAX (a motor at its current limit works), and only for a wheel turning its setpoint's way that counts this tick (a reversed encoder's wheel turning toward its setpoint reads against it)
#define WC_CURRENT_SENSE_MAX 30.0f // A: a current sense reading more, either way, has failed (a cut output reads 0 V, -62 A; one shorted to 5 V, +62 A): EVT:FAULT,CURRENT_SENSE. The driver limits each motor to 13 A

// ---- Hill hold and rollaway (parked without a fault; protocol/PROTOCOL.md) ---
#define WC_HOLD_DEADBAND_COUNTS 10 // encoder counts (1 mm of travel) a held wheel may be off the count it stopped at before the hold drives it back
#define WC_HOLD_GAIN 1             // hold duty per count of error beyond HOLD_DEADBAND_COUNTS
#define WC_HOLD_PWM_MAX 64         // the hold's largest duty (25 %): past the driver's 13 A current limit at a standstill (duty 42), so the brake is the hardest the driver gives
#define WC_OVERSPEED_PWM 26        // duty (10 %) at or above which a wheel driven against its motion is braking it (at speed the current limit binds at a low duty)
#define WC_OVERSPEED_MARGIN 1.0f   // rad/s a wheel braked at OVERSPEED_PWM may run beyond its setpoint before it counts as overspeeding
#define WC_OVERSPEED_GAIN 0.3f     // rad/s a wheel must gain over a run of overspeeding ticks, from the speed before its first: gravity beats the brakes (within its rated grade a braked chair slows, however slowly)
#define WC_OVERSPEED_TICKS 2       // ticks in a row overspeeding (0.1 s) at least, with OVERSPEED_GAIN gained over them: EVT:OVERSPEED, the chair parks braking hardest
#define WC_OVERSPEED_ONE_TICKS 6   // ticks in a row (0.3 s) that one wheel overspeeds, OVERSPEED_GAIN faster than before its first, while the other brakes at the current limit and holds: its motor does not brake (EVT:FAULT,MOTOR_L/R)
#define WC_GRADE_PWM 128           // duty (50 %) toward its setpoint at or above which a wheel short of it is straining: both straining is the chair's limit (a grade), not a fault
#define WC_GRADE_STALL 0.25f       // fraction of its setpoint below which a wheel showing effort without progress, no more than its partner, is stalling on the grade: both wheels so is EVT:STALLED_ON_GRADE (within the rated grade a chair slows on the climb, to no less than 84 % of full speed at full duty, and keeps climbing)
#define WC_ROLLAWAY_COUNTS 209     // encoder counts (2 cm of travel: 0.02 m / (2 pi WHEEL_RADIUS) x CPR) a held wheel may be pushed off its count before EVT:ROLLAWAY

// ---- Modes (printed as MODE:WHEEL / CMDVEL / PPM) --------------------------
#define WC_MODE_WHEEL 0
#define WC_MODE_CMDVEL 1
#define WC_MODE_PPM 2

// ---- The drive limits: a drive profile's speeds and ramps, runtime parameters (docs/safety.md, "Drive limits"); each default sits past what the wheels can do, so that it limits nothing ---
#define WC_DRIVE_SPEED_MIN 0.1f    // m/s: fwd_speed, rev_speed in [DRIVE_SPEED_MIN, DRIVE_SPEED_MAX]
#define WC_DRIVE_SPEED_MAX 2.69f   // m/s: the default of fwd_speed and rev_speed, past the chair's 2.68 (MAX_WHEEL_SPEED at the rim): the top speed forward and back, of the chair's centre
#define WC_DRIVE_ACCEL_MIN 0.1f    // m/s^2: drive_accel, drive_decel in [DRIVE_ACCEL_MIN, DRIVE_ACCEL_MAX]
#define WC_DRIVE_ACCEL_MAX 3.0f    // m/s^2: the default of drive_accel (speeding up) and drive_decel (slowing down), each a wheel's ramp (divided by WHEEL_RADIUS) within max_accel, which stays the ceiling: 3.0 is 19.7 rad/s^2, past ACCEL_MAX
#define WC_TURN_SPEED_MIN 0.1f     // rad/s: turn_speed in [TURN_SPEED_MIN, TURN_SPEED_MAX]
#define WC_TURN_SPEED_MAX 9.5f     // rad/s: the default of turn_speed, the chair's top turn rate, past the 9.41 of the wheels at MAX_WHEEL_SPEED either way
#define WC_TURN_ACCEL_MIN 0.5f     // rad/s^2: turn_accel in [TURN_ACCEL_MIN, TURN_ACCEL_MAX]
#define WC_TURN_ACCEL_MAX 40.0f    // rad/s^2: the default of turn_accel, how fast the turn rate may change (the wheels' difference, WHEELBASE / 2 / WHEEL_RADIUS a rad/s^2 each: 74.8 rad/s^2 at 40, past ACCEL_MAX)
#define WC_TURN_AT_SPEED 1.0f      // the default of turn_at_speed in [0, 1]: the share of turn_speed left at the top speed (the turn rate falls linearly with the speed toward it; DX's "Turning @ Full Speed")
#define WC_TREMOR_DAMPING 0.0f     // the default of tremor_damping in [0, TREMOR_DAMPING_MAX]: the share of the last damped goal each tick keeps, in PPM mode (the joystick), toward the stick's targets: goal += (1 - tremor_damping) x (target - goal), a first-order low-pass of the stick at 20 Hz (0: off, the targets as they are; a stick at neutral, both targets 0, is never damped: a stop is not delayed). DX's and R-net's tremor damping
#define WC_TREMOR_DAMPING_MAX 0.9f // tremor_damping at most: a 0.47 s time constant, a 5 Hz tremor sampled at 20 Hz down to 7 % of itself
#define WC_PROFILE_COUNT 4         // drive profiles: rows of the eight drive limits (the [[profile]] presets below), one in force (the parameter profile); set: of a drive limit changes the row in force, save stores every row
#define WC_PROFILE 0               // the default of profile in [0, PROFILE_COUNT - 1]: the profile in force at boot without a saved one, and after defaults
#define WC_PROFILE_MAX 3           // profile in [0, PROFILE_MAX]: PROFILE_COUNT - 1

// ---- Parameters in EEPROM (save / defaults; protocol/PROTOCOL.md) ----------
#define WC_EEPROM_SIZE 4096        // bytes of the ATmega2560's EEPROM, erased to 0xFF
#define WC_EEPROM_PARAMS_ADDR 0    // EEPROM address of the parameter block
#define WC_EEPROM_LAYOUT 7         // the block's first byte: its layout version (a blank EEPROM holds 0xFF; 1 was the block before feedback_form, 2 before brake_fitted, 3 before the drive limits, 4 before the table of drive profiles, 5 before stall_timeout, 6 before tremor_damping)

// ---- Ranges of the runtime parameters (get:/set:; the defaults are the constants above) ---
#define WC_GAIN_P_MIN 1.0f         // kp_l, kp_r in [GAIN_P_MIN, GAIN_P_MAX] (tests/firmware/test_gain_safety.py: pure integral control oscillates)
#define WC_GAIN_P_MAX 10.0f
#define WC_GAIN_I_MIN 0.01f        // ki_l, ki_r in [GAIN_I_MIN, GAIN_I_MAX] (the anti-windup divides by ki)
#define WC_GAIN_I_MAX 10.0f
#define WC_GAIN_D_MAX 0.2f         // kd_l, kd_r in [0, GAIN_D_MAX]
#define WC_MAX_WHEEL_MIN 0.1f      // max_wheel in [MAX_WHEEL_MIN, MAX_WHEEL_SPEED] rad/s
#define WC_ACCEL_MIN 0.5f          // max_accel in [ACCEL_MIN, ACCEL_MAX] rad/s^2
#define WC_ACCEL_MAX 7.0f          // the largest ramp the chair can follow: the motors' braking limit (ChairParams.max_braking, 198 N) gives 7.37 rad/s^2 for the modelled chair with an 80 kg occupant (tests/firmware/test_gain_safety.py)
#define WC_DECEL_MIN 5.0f          // estop_decel in [DECEL_MIN, DECEL_MAX] rad/s^2
#define WC_DECEL_MAX 50.0f
#define WC_WATCHDOG_MIN_MS 100     // watchdog_ms in [WATCHDOG_MIN_MS, WATCHDOG_MAX_MS]
#define WC_WATCHDOG_MAX_MS 1000    // docs/safety.md: the stopping distance grows with it
#define WC_FEEDBACK_FORM 0         // default of feedback_form: 0, the feedback line ENC:<l>,<r>,VEL:<l>,<r>,MODE:<m> alone
#define WC_FEEDBACK_FORM_MAX 1     // feedback_form in [0, FEEDBACK_FORM_MAX]; 1 appends ,r[pn]<|vel r|>,l[pn]<|vel l|> to each unframed feedback line (ros2_control hardware interfaces)
#define WC_BRAKE_FITTED_MAX 1      // brake_fitted in [0, BRAKE_FITTED_MAX]

// ---- The drive profiles' presets ([[profile]]), rows of fwd_speed, rev_speed, drive_accel, drive_decel, turn_speed, turn_accel, turn_at_speed, tremor_damping ---
#define WC_PROFILE_PRESETS { \
  { 2.69f, 2.69f, 3.0f, 3.0f, 9.5f, 40.0f, 1.0f, 0.0f },  /* 0: open */ \
  { 1.0f, 0.5f, 0.5f, 0.6f, 1.0f, 2.0f, 0.5f, 0.0f },  /* 1: indoor */ \
  { 2.0f, 0.8f, 0.7f, 0.7f, 1.5f, 3.0f, 0.4f, 0.0f },  /* 2: outdoor */ \
  { 0.6f, 0.4f, 0.4f, 0.5f, 0.8f, 1.5f, 0.8f, 0.0f },  /* 3: attendant */ \
}

#endif
