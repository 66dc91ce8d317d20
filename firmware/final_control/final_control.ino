// final_control: wheel-velocity controller for the wcdrive power wheelchair.
//
// Arduino Mega 2560 at 16 MHz driving a Cytron SmartDriveDuo (PWM + DIR per
// motor). Behaviour follows the seed guide sections 1.4 to 1.8; the fixes to
// the seed's defects are listed in README.md beside this file.
//
// Structure of one loop() pass (nothing in it blocks):
//   1. every byte waiting in the UART RX buffer goes through processByte(),
//      which frames and parses commands from a fixed buffer;
//   2. when 50 ms of millis() have passed, controlTick() runs the controller
//      and sends one feedback line.
// Everything a command changes takes effect at the next control tick.
//
// The controller state is kept in plain globals with stable names so that the
// simavr harness (wcdrive/boards/simavr/) can read them from SRAM by symbol. The
// Python port in wcdrive/firmware/ mirrors every function here, bit for bit.

#include <Arduino.h>
#include <math.h>
#include <avr/pgmspace.h>
#include <stdlib.h>
#include <string.h>
#include <util/atomic.h>
#include <util/crc16.h>
#include <avr/wdt.h>
#include <avr/eeprom.h>

#include "wc_config.h"
#include "HardwareSerial_private.h"   // the core's HardwareSerial constructor and TX interrupt

#if SERIAL_TX_BUFFER_SIZE < 1024
#warning "build with -DSERIAL_TX_BUFFER_SIZE=1024 (see README.md): output lines may be dropped"
#endif

// ---------------------------------------------------------------------------
// Encoder state, written by the interrupts.
//
// The encoder interrupts are hand-written (ISR_NAKED, below): 54 cycles for the left
// wheel and 55 for the right, the chip's 5-cycle interrupt entry, the vector's jmp and
// reti included (firmware/final_control/README.md lists each path; a test reads the
// disassembly). To be that short, an interrupt only adds the step to an 8-bit
// accumulator (encAccL/R, illAccL/R); Timer0's compare-A interrupt, once a Timer0 period
// (1.024 ms), folds them into the 32-bit counts. Fewer than WC_STORM_EDGES (< 128) edges
// reach an encoder in a period, or the storm guard masks it, so an accumulator never
// overflows. Readers take count + accumulator with interrupts off.
// ---------------------------------------------------------------------------
volatile int32_t encoderValueL = 0;
volatile int32_t encoderValueR = 0;
volatile uint32_t illegalL = 0;   // transitions with both channels changed
volatile uint32_t illegalR = 0;
volatile int8_t encAccL = 0, encAccR = 0;      // steps since the last fold
volatile uint8_t illAccL = 0, illAccR = 0;     // illegal transitions since the last fold

// Step of a transition, indexed by (previous pins << 2) | pins as the interrupts read
// them: 1 forward, 0xFF (-1) backward, 0 no change, QUAD_ILLEGAL both channels changed.
// The left encoder's pins come swapped (A in bit 0: PE4, B in bit 1: PE5); the right
// one's in order (A in bit 1: PD3, B in bit 0: PD2). Both are QUAD_TABLE of
// wcdrive/firmware/quadrature.py, the states read A << 1 | B. 16-aligned, in RAM: the
// interrupt indexes them with one "ori".
#define QUAD_ILLEGAL 0x80
__attribute__((used, aligned(16))) static const int8_t QUAD_L[16] = {
  0, 1, -1, (int8_t)QUAD_ILLEGAL, -1, 0, (int8_t)QUAD_ILLEGAL, 1,
  1, (int8_t)QUAD_ILLEGAL, 0, -1, (int8_t)QUAD_ILLEGAL, -1, 1, 0,
};
__attribute__((used, aligned(16))) static const int8_t QUAD_R[16] = {
  0, -1, 1, (int8_t)QUAD_ILLEGAL, 1, 0, (int8_t)QUAD_ILLEGAL, -1,
  -1, (int8_t)QUAD_ILLEGAL, 0, 1, (int8_t)QUAD_ILLEGAL, 1, -1, 0,
};

// Storm guard: each encoder may make WC_STORM_EDGES edges in one Timer0 period (the
// countdown stormEdgesL/R, set again by TIMER0_COMPA); the last one masks its two
// interrupts and sets its storm flag, which the control tick latches as an
// implausible-encoder fault. So no edge rate holds loop() for more than WC_STORM_EDGES
// interrupts per encoder a period; "reset" unmasks.
volatile uint8_t stormL = 0, stormR = 0;
volatile uint8_t stormEdgesL = WC_STORM_EDGES, stormEdgesR = WC_STORM_EDGES;
extern uint8_t stormTickL, stormTickR;   // the flags as the control tick latched them (below)

// The pins as the interrupts read them; GPIOR1/GPIOR2 keep the last reading << 2 (GPIOR0
// holds SREG while an encoder interrupt runs: they do not nest).
static inline uint8_t readEncoderL() { return (uint8_t)((PINE >> 4) & 0x03); }
static inline uint8_t readEncoderR() { return (uint8_t)((PIND >> 2) & 0x03); }

// Interruptible (ISR_NOBLOCK): the 32-bit additions take about 150 cycles, which an
// encoder interrupt must not wait for (at 70,000 edges/s an encoder changes every 228
// cycles). Only taking the accumulators is done with interrupts off.
ISR(TIMER0_COMPA_vect, ISR_NOBLOCK) {
  int8_t stepsL, stepsR;
  uint8_t illL, illR;
  cli();
  stepsL = encAccL;
  stepsR = encAccR;
  illL = illAccL;
  illR = illAccR;
  encAccL = encAccR = 0;
  illAccL = illAccR = 0;
  stormEdgesL = WC_STORM_EDGES;
  stormEdgesR = WC_STORM_EDGES;
  sei();
  encoderValueL += stepsL;
  encoderValueR += stepsR;
  illegalL += illL;
  illegalR += illR;
}

// One encoder interrupt: cycles in the right column, 5 (entry) + 3 (jmp) before it.
#define ENCODER_ISR(PINS, LAST, TABLE, EDGES, ACC, ILL, STORM, BIT1, BIT2)          \
  asm volatile(                                                                          \
      "push r24               \n\t" /* 2 */                                              \
      "in   r24, __SREG__     \n\t" /* 1 */                                              \
      "out  %[save], r24      \n\t" /* 1  SREG kept in GPIOR0 */                         \
      "push r30               \n\t" /* 2 */                                              \
      "push r31               \n\t" /* 2 */                                              \
      PINS                          /* 3 (left) or 4 (right): r24 = pins, 0..3 */        \
      "in   r30, %[last]      \n\t" /* 1  the last reading << 2 */                       \
      "or   r30, r24          \n\t" /* 1 */                                              \
      "lsl  r24               \n\t" /* 1 */                                              \
      "lsl  r24               \n\t" /* 1 */                                              \
      "out  %[last], r24      \n\t" /* 1 */                                              \
      "ori  r30, lo8(%[tab])  \n\t" /* 1 */                                              \
      "ldi  r31, hi8(%[tab])  \n\t" /* 1 */                                              \
      "ld   r24, Z            \n\t" /* 2  the step */                                    \
      "lds  r30, %[edges]     \n\t" /* 2  storm guard */                                 \
      "dec  r30               \n\t" /* 1 */                                              \
      "sts  %[edges], r30     \n\t" /* 2 */                                              \
      "breq 3f                \n\t" /* 1  the period's last edge: mask, below */        \
      "1: cpi r24, 0x80       \n\t" /* 1 */                                              \
      "breq 2f                \n\t" /* 1  an illegal transition: below */               \
      "lds  r30, %[acc]       \n\t" /* 2 */                                              \
      "add  r30, r24          \n\t" /* 1 */                                              \
      "sts  %[acc], r30       \n\t" /* 2 */                                              \
      "4: pop r31             \n\t" /* 2 */                                              \
      "pop  r30               \n\t" /* 2 */                                              \
      "in   r24, %[save]      \n\t" /* 1 */                                              \
      "out  __SREG__, r24     \n\t" /* 1 */                                              \
      "pop  r24               \n\t" /* 2 */                                              \
      "reti                   \n\t" /* 5 */                                              \
      "2: lds r30, %[ill]     \n\t"                                                      \
      "inc  r30               \n\t"                                                      \
      "sts  %[ill], r30       \n\t"                                                      \
      "rjmp 4b                \n\t"                                                      \
      "3: in r30, %[eimsk]    \n\t" /* the storm guard: this encoder off, */           \
      "andi r30, %[keep]      \n\t"                                                      \
      "out  %[eimsk], r30     \n\t"                                                      \
      "sts  %[storm], r31     \n\t" /* its flag set (r31: the table's page, not 0) */   \
      "rjmp 1b                \n\t" /* and this edge counts */                          \
      ::[save] "I"(_SFR_IO_ADDR(GPIOR0)), [last] "I"(_SFR_IO_ADDR(LAST)), [tab] "i"(TABLE),    \
      [edges] "i"(&EDGES), [acc] "i"(&ACC), [ill] "i"(&ILL), [storm] "i"(&STORM),         \
      [eimsk] "I"(_SFR_IO_ADDR(EIMSK)), [keep] "n"(0xFF & ~((1 << BIT1) | (1 << BIT2))),          \
      [pine] "I"(_SFR_IO_ADDR(PINE)),                                                     \
      [pind] "I"(_SFR_IO_ADDR(PIND)))

// Left encoder: A on PE4 (pin 2), B on PE5 (pin 3); INT4 and INT5.
ISR(INT4_vect, ISR_NAKED) {
  ENCODER_ISR("in r24, %[pine] \n\t swap r24 \n\t andi r24, 0x03 \n\t", GPIOR1, QUAD_L, stormEdgesL,
              encAccL, illAccL, stormL, INT4, INT5);
}
ISR(INT5_vect, ISR_ALIASOF(INT4_vect));

// Right encoder: A on PD3 (pin 18), B on PD2 (pin 19); INT3 and INT2.
ISR(INT3_vect, ISR_NAKED) {
  ENCODER_ISR("in r24, %[pind] \n\t lsr r24 \n\t lsr r24 \n\t andi r24, 0x03 \n\t", GPIOR2, QUAD_R,
              stormEdgesR, encAccR, illAccR, stormR, INT2, INT3);
}
ISR(INT2_vect, ISR_ALIASOF(INT3_vect));

// "reset" after an implausible-encoder fault: the pins read afresh, the interrupts on
// again. Only an encoder whose storm a tick has latched (stormTickL/R: the fault this
// reset clears): one masked since the last tick stays masked, and the next tick latches
// its fault. (Unmasked at once, a storm between a tick and a reset went unreported, and
// the edges lost while it was masked with it.)
static void unmaskEncoders() {
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    // The pins are read last, the interrupts already on (taken once this block ends): an
    // edge before the read is in the state read, one after it sets its flag and is
    // taken from that state. (Read first, an edge between the read and the unmask was
    // lost, and the next one counted as an illegal transition.)
    if (stormL && stormTickL) {
      EIFR = _BV(INTF4) | _BV(INTF5);
      EIMSK |= _BV(INT4) | _BV(INT5);
      stormEdgesL = WC_STORM_EDGES;
      stormL = 0;
      GPIOR1 = (uint8_t)(readEncoderL() << 2);
    }
    if (stormR && stormTickR) {
      EIFR = _BV(INTF2) | _BV(INTF3);
      EIMSK |= _BV(INT2) | _BV(INT3);
      stormEdgesR = WC_STORM_EDGES;
      stormR = 0;
      GPIOR2 = (uint8_t)(readEncoderR() << 2);
    }
  }
}

// ---------------------------------------------------------------------------
// Controller state (read by the simulator by name).
// ---------------------------------------------------------------------------
uint8_t mode = WC_MODE_CMDVEL;
float targetL = 0.0f, targetR = 0.0f;       // commanded wheel speeds, rad/s
float setpointL = 0.0f, setpointR = 0.0f;   // ramped setpoints fed to the PID
float rawVelL = 0.0f, rawVelR = 0.0f;       // measured this tick, rad/s
float filtVelL = 0.0f, filtVelR = 0.0f;     // IIR-filtered velocity
float integralL = 0.0f, integralR = 0.0f;
// The integrals and setpoints when the last emergency ramp began (resumedIntegral).
float haltIntegralL = 0.0f, haltIntegralR = 0.0f;
float haltSetpointL = 0.0f, haltSetpointR = 0.0f;
float prevMeasL = 0.0f, prevMeasR = 0.0f;   // last filtered velocity seen by the PID
float outputL = 0.0f, outputR = 0.0f;       // PID output, -100..100
uint8_t pwmL = 0, pwmR = 0;                 // duty written to the driver
uint8_t dirL = HIGH, dirR = HIGH;
int32_t encTickL = 0, encTickR = 0;         // counts latched at the last tick
int32_t prevEncL = 0, prevEncR = 0;
uint32_t illTickL = 0, illTickR = 0;        // illegal-transition counts latched at the last tick
uint8_t stormTickL = 0, stormTickR = 0;     // the ISRs' storm flags latched at the last tick
uint32_t lastControlTime = 0;               // millis() the last tick was due at (the 50 ms grid)
uint32_t lastTickTime = 0;                  // millis() the last tick ran at (the counts' interval)
uint32_t lateTicks = 0;                     // ticks more than a period late: the grid restarted
uint32_t tickCount = 0;
uint16_t freeRam = 0;                       // bytes between the heap and the stack, before a tick

// Runtime parameters (get:/set:, protocol v2), the compile-time values at boot.
float kpL = WC_KP_L, kiL = WC_KI_L, kdL = WC_KD_L;
float kpR = WC_KP_R, kiR = WC_KI_R, kdR = WC_KD_R;
float maxWheel = WC_MAX_WHEEL_SPEED;        // rad/s: WHEEL range, CMDVEL and PPM cap
float maxAccel = WC_MAX_ACCEL;              // rad/s^2: normal setpoint ramp
float estopDecel = WC_EMERGENCY_DECEL;      // rad/s^2: watchdog, PPM loss and e-stop ramp
// The drive limits, a drive profile's (docs/safety.md, "Drive limits"): the cap of what
// the host may ask on every command path. Each default limits nothing.
float fwdSpeed = WC_DRIVE_SPEED_MAX;        // m/s: top speed forward, of the chair's centre
float revSpeed = WC_DRIVE_SPEED_MAX;        // m/s: top speed backward
float driveAccel = WC_DRIVE_ACCEL_MAX;      // m/s^2: a wheel speeding up (within maxAccel)
float driveDecel = WC_DRIVE_ACCEL_MAX;      // m/s^2: a wheel slowing down (within maxAccel)
float turnSpeed = WC_TURN_SPEED_MAX;        // rad/s: top turn rate
float turnAccel = WC_TURN_ACCEL_MAX;        // rad/s^2: how fast the turn rate may change
float turnAtSpeed = WC_TURN_AT_SPEED;       // the share of turnSpeed left at the top speed
float tremorDamping = WC_TREMOR_DAMPING;    // in PPM mode, the share of the last goal a tick keeps
float dampedL = 0.0f, dampedR = 0.0f;       // the stick's targets through the damping (dampedTargets)
// The drive profiles (docs/safety.md, "Drive profiles"): WC_PROFILE_COUNT rows of the
// eight drive limits above, in their parameter table order; the row of the profile in
// force is the limits above, which set: changes together with it. In .noinit: setup()
// fills it from the presets (presetProfiles) before loadParams, so reset's clearing
// loop need not.
#define PROFILE_FLOATS 8
uint8_t profile = WC_PROFILE;               // runtime parameter profile: the row in force
float profileTable[WC_PROFILE_COUNT][PROFILE_FLOATS] __attribute__((section(".noinit")));
static const float PROFILE_PRESETS[WC_PROFILE_COUNT][PROFILE_FLOATS] PROGMEM = WC_PROFILE_PRESETS;
uint16_t watchdogMs = WC_WATCHDOG_MS;
uint8_t feedbackForm = WC_FEEDBACK_FORM;    // 1: the unframed feedback line ends in the wheels' r/l fields

float lastTravel = 0.0f;                    // m/s of travel of the last command
// Pivot on reversal: stop, rotate in place for WC_PIVOT_TICKS, then the command.
#define PIVOT_NONE 0
#define PIVOT_STOPPING 1
#define PIVOT_ROTATING 2
uint8_t pivotPhase = PIVOT_NONE;
uint8_t pivotTicksLeft = 0;
float pendingL = 0.0f, pendingR = 0.0f;     // command waiting for the pivot to end

bool cmdSinceTick = false;                  // a valid command arrived since the last tick
bool watchdogArmed = false;
uint32_t lastCmdTime = 0;                   // millis() of the tick that saw the last command
bool emergencyStop = false;                 // ramp down at WC_EMERGENCY_DECEL
bool ppmLost = false;
uint8_t stillTicks = 0;
volatile bool parked = true;                       // PID off, integrators reset: the hold (duty 0 after a fault that leaves it no encoder)

// The hold (parked; after a fault, on the healthy wheel's counts): each wheel driven back
// toward the count it came to rest at (holdRef*), by holdMotor(). While a wheel still
// slows after parking, its reference follows its count (holdStep*: the count step of its
// last tick, 0 once the reference is fixed), so a chair that coasts to a stop on the
// level holds where it stopped.
bool holding = false;                      // parked, the hold drives a wheel (both without a fault)
int32_t holdRefL = 0, holdRefR = 0;
int32_t holdStepL = 0, holdStepR = 0;
bool holdRollaway = false;                 // EVT:ROLLAWAY sent for this hold, or it began braking hardest
volatile bool brakeReleased = false;       // WC_PIN_BRAKE HIGH (volatile: kept for the harness)
// The parking brake with brake_fitted 1 (docs/safety.md, "The parking brake"): engaged
// WC_BRAKE_ACTIVE_TICKS after the chair parks (at once on a fault), the motors then
// unpowered; released only for a motion asked for, the hold driving first. Without a
// brake (brake_fitted 0) WC_PIN_BRAKE is LOW whenever the PID does not drive.
#define BRAKE_ENGAGED 0     // the pin LOW, the brake holds: parked, the motors unpowered
#define BRAKE_PRELOAD 1     // a motion asked for: the hold drives, the pin still LOW
#define BRAKE_RELEASING 2   // the pin HIGH, the hold on, until the brake has let go
#define BRAKE_RELEASED 3    // the PID drives; parked, the hold brakes WC_BRAKE_ACTIVE_TICKS
#define BRAKE_ENGAGING 4    // the pin LOW, the hold (or the PID) on, until the brake holds
uint8_t brakeFitted = WC_BRAKE_FITTED;      // runtime parameter brake_fitted
uint8_t brakePhase = BRAKE_ENGAGED;         // as from reset: the pin an input, pulled down
uint8_t brakeTicks = 0;                     // ticks in this phase (BRAKE_RELEASED: parked)
uint8_t brakeStatusTick = 0;                // 1: WC_PIN_BRAKE_STATUS read LOW this tick
uint8_t brakeStatusTicks = 0;               // ticks in a row it has, the brake fitted
uint8_t overspeedTicksL = 0, overspeedTicksR = 0;   // ticks in a row overspeeding (overspeeding)
float overspeedFromL = 0.0f, overspeedFromR = 0.0f; // the speed the PID ran on before that run began
bool limitLatched = false;                 // the chair's limit halted it: motion refused (ERR:limit) until a stop

bool estopLatched = false;                  // e-stop: motion refused until "reset"

// Neutral before motion (ISO 7176-14, control signal at switch-on): after a boot, a fault
// or e-stop reset, a watchdog stop and a PPM loss, motion is refused (ERR:neutral) until
// a neutral (zero) command has stood for WC_NEUTRAL_TICKS ticks with no motion command
// after it. A host that streams its last command across a reset does not move the chair.
bool needNeutral = true;                    // motion refused until neutral is confirmed
bool neutralSeen = false;                   // a neutral command came, no motion command since
uint8_t neutralTicks = 0;                   // ticks since then
bool notNeutralSent = false;                // a motion command refused in this wait
bool notNeutralPending = false;             // ...and EVT:NOT_NEUTRAL not sent yet (the tick sends it)
uint8_t notNeutralTicks = 0;                // ticks of this wait without a neutral command
bool neutralFault = false;                  // EVT:DEFLECTED: refused for WC_NEUTRAL_FAULT_TICKS

// Inhibit inputs (ISO 7176-14, inhibit while charging; the seat raised): two pins read
// at each tick, active LOW, debounced over WC_INHIBIT_DEBOUNCE_TICKS ticks. Engaged,
// an input of speed 0 stops the chair along the normal ramp and refuses motion
// (ERR:inhibit); any other caps the wheels at its share of max_wheel. A latching input
// stays engaged until released and a reset. Released, motion needs neutral first.
// Bit 0 is input 1, bit 1 input 2, bit 2 the brake's manual release (push mode): read as
// a third input that inhibits driving and never latches; parked in push mode, the motors
// freewheel (pushMotor) instead of holding.
#define INHIBIT_PUSH 4
#define INHIBIT_STOP_MASK ((WC_INHIBIT_1_SPEED == 0.0f ? 1 : 0) | (WC_INHIBIT_2_SPEED == 0.0f ? 2 : 0) | INHIBIT_PUSH)
#define INHIBIT_LATCH_MASK ((WC_INHIBIT_1_LATCH ? 1 : 0) | (WC_INHIBIT_2_LATCH ? 2 : 0))
uint8_t inhibitTick = 0;                    // the inputs as the tick read them (1: active, pin LOW)
uint8_t inhibitStable = 0;                  // ...debounced
uint8_t inhibitCountL = 0, inhibitCountR = 0;   // ticks input 1 / 2 has read other than inhibitStable
uint8_t inhibitCountP = 0;                  // ...and the manual release
uint8_t inhibitLatched = 0;                 // latching inputs engaged, until released and a reset
uint8_t inhibitOn = 0;                      // the inputs engaged as of the last tick
uint8_t inhibitPending = 0;                 // events to send: bit 0/1 input 1 on/off, bit 2/3 input 2, 4/5 push

// The motors' heat, estimated (no sensor): each winding's temperature, deg C, from its
// copper loss (windingLoss); above WC_THERMAL_ROLLBACK_TEMP the current limit and the top
// speed roll back (docs/safety.md, "Motor heat").
float windingTempL = WC_THERMAL_AMBIENT, windingTempR = WC_THERMAL_AMBIENT;
uint8_t thermalRollback = 0;                // the rollback on (EVT:THERMAL,1 sent or pending)
uint8_t thermalPending = 0;                 // events to send: bit 0 THERMAL,1, bit 1 THERMAL,0

// The supply, measured at WC_PIN_SUPPLY (A0) through a divider: the ADC count the tick
// read, the battery voltage filtered (0 until the first tick), the low-battery rollback
// (docs/safety.md, "The battery").
uint16_t supplyTick = 0;
float supplyVolts = 0.0f;
uint8_t batteryLow = 0;                     // the rollback on (EVT:BATTERY,1 sent or pending)
uint8_t batteryPending = 0;                 // events to send: bit 0 BATTERY,1, bit 1 BATTERY,0

// The motors' currents, measured at WC_PIN_CURRENT_L/R (A1, A2) by Hall sensors: the ADC
// interrupt converts them after the tick's start (adcCurrentL/R), then starts the
// supply's conversion for the next tick to read; the tick reads the counts the last one
// left (currentTickL/R). A wheel held at its current limit for stallTimeout seconds
// stops the chair (docs/safety.md, "Stall timeout").
volatile uint16_t adcCurrentL = WC_CURRENT_ZERO_COUNTS, adcCurrentR = WC_CURRENT_ZERO_COUNTS;
uint16_t currentTickL = WC_CURRENT_ZERO_COUNTS, currentTickR = WC_CURRENT_ZERO_COUNTS;
float stallTimeout = WC_STALL_TIMEOUT;      // s (the parameter stall_timeout)
float stallTime = 0.0f;                     // s a wheel has been held at its current limit

// Faults (EVT:FAULT,<name>; docs/safety.md): latched until "reset", motion refused, motors off.
#define FAULT_STALL_L 0x01
#define FAULT_STALL_R 0x02
#define FAULT_REVERSED_L 0x04
#define FAULT_REVERSED_R 0x08
#define FAULT_IMPLAUSIBLE_L 0x10
#define FAULT_IMPLAUSIBLE_R 0x20
#define FAULT_DRIVER 0x40
#define FAULT_MOTOR_L 0x80
#define FAULT_MOTOR_R 0x100
#define FAULT_BRAKE_OPEN 0x200
#define FAULT_BRAKE_SHORT 0x400
#define FAULTS_BRAKE (FAULT_BRAKE_OPEN | FAULT_BRAKE_SHORT)
#define FAULT_OVERHEAT_L 0x800
#define FAULT_OVERHEAT_R 0x1000
#define FAULT_UNDERVOLT 0x2000
#define FAULT_CURRENT_SENSE 0x4000
// The faults after which a wheel's encoder is no longer trusted: its own, and the driver's.
#define FAULTS_UNTRUSTED_L (FAULT_STALL_L | FAULT_REVERSED_L | FAULT_IMPLAUSIBLE_L | FAULT_MOTOR_L | FAULT_DRIVER)
#define FAULTS_UNTRUSTED_R (FAULT_STALL_R | FAULT_REVERSED_R | FAULT_IMPLAUSIBLE_R | FAULT_MOTOR_R | FAULT_DRIVER)
uint16_t faultFlags = 0;
uint8_t stallTicksL = 0, stallTicksR = 0;   // ticks driven without a count
uint8_t reverseTicksL = 0, reverseTicksR = 0;   // ticks measured against the setpoint
uint8_t runawayTicksL = 0, runawayTicksR = 0;   // ticks running away (runsAway)
// Effort without progress: the duty and speed (toward the setpoint) when the setpoint
// last changed or the wheel last gained speed; the lowest duty since.
uint8_t effortPwmL = 0, effortPwmR = 0;
uint8_t effortTicksL = 0, effortTicksR = 0;   // consecutive ticks of that effort
float effortSpeedL = 0.0f, effortSpeedR = 0.0f;
float effortSetpointL = 0.0f, effortSetpointR = 0.0f;
bool tlmEnabled = false;                    // after "hello": TLM lines, and v3 frames only
bool linesFramed = false;                   // after "hello:4": every line framed (protocol v4)
uint8_t lineCounter = 0;                    // the next framed line's counter (#NN)
bool unframedLine = false;                  // the line being parsed is not a v3 frame
uint16_t lastSeq = 0;                       // sequence number of the last framed line
uint32_t rxCount = 0;                       // bytes received (through processByte)
uint32_t rxGaps = 0;                        // losses loop() met in the byte stream (rxGap's "lost")
uint32_t rxLostTick = 0;                    // rxLost (the RX interrupt's count) latched at the last tick

uint32_t rejectedCount = 0;                 // every rejected command
uint32_t crcRejected = 0;                   // framed lines with a bad or missing CRC
uint32_t errSuppressed = 0;                 // replies not sent (rate limit)
uint32_t txDropped = 0;                     // lines not sent: over the output budget (txCredit)
uint32_t txRingFull = 0;                    // lines not sent: no room in the TX ring (never, if the budget holds)
uint16_t txCredit = WC_TX_CREDIT_BOOT;      // bytes the board may still queue (the output budget)
uint8_t errLinesThisTick = 0;

// ---------------------------------------------------------------------------
// The serial port. The core's Serial (HardwareSerial0.cpp) drops a received byte silently
// when its 64-byte ring is full and ignores the USART's data overrun flag. WcSerial is the
// core's class (the same rings and TX path) with its own receive interrupt: it counts
// every loss (rxLost) and marks where in the byte stream it happened, so that loop() can
// throw away the line that lost a byte (rxGap, ERR:overrun) instead of splicing its ends.
// HardwareSerial0.o is then not linked (nothing names its Serial).
// ---------------------------------------------------------------------------
volatile uint32_t rxLost = 0;               // bytes dropped for a full ring, plus USART overruns
volatile uint8_t rxLostAt[SERIAL_RX_BUFFER_SIZE];   // losses just before each ring slot (255 at most)

class WcSerial : public HardwareSerial {
 public:
  using HardwareSerial::HardwareSerial;

  // USART0_RX: the byte and its status. DOR0 set: frames were lost before this one; a
  // frame or parity error: this one is garbage; a full ring: this one is dropped. Each
  // marks a gap before the ring slot the next byte will take.
  inline void rxInterrupt() {
    uint8_t status = UCSR0A;   // the registers themselves, not through the class's pointers
    uint8_t c = UDR0;
    rx_buffer_index_t head = _rx_buffer_head;
    rx_buffer_index_t next = (rx_buffer_index_t)((head + 1) % SERIAL_RX_BUFFER_SIZE);
    if (status & (_BV(DOR0) | _BV(FE0) | _BV(UPE0))) {
      rxLost++;
      if (rxLostAt[head] != 255) rxLostAt[head]++;
      if (status & (_BV(FE0) | _BV(UPE0))) return;
    }
    if (next == _rx_buffer_tail) {
      rxLost++;
      if (rxLostAt[head] != 255) rxLostAt[head]++;
      return;
    }
    _rx_buffer[head] = c;
    _rx_buffer_head = next;
  }

  // USART0_UDRE: the next byte of the TX ring, as the core's _tx_udr_empty_irq does it,
  // but inline with the registers themselves: the core's is a call, and the registers it
  // saves cost 136 cycles an interrupt, which an encoder interrupt may wait for.
  inline void txInterrupt() {
    tx_buffer_index_t tail = _tx_buffer_tail;
    UDR0 = _tx_buffer[tail];
    tail = (tx_buffer_index_t)((tail + 1) % SERIAL_TX_BUFFER_SIZE);
    _tx_buffer_tail = tail;
    UCSR0A = (uint8_t)((UCSR0A & (_BV(U2X0) | _BV(MPCM0))) | _BV(TXC0));
    if (_tx_buffer_head == tail) UCSR0B &= (uint8_t)~_BV(UDRIE0);
  }

  // The next received byte (-1: none), and the losses counted just before it (0: none;
  // an overrun counts one, however many frames it cost).
  int readMarked(uint8_t& lost) {
    rx_buffer_index_t tail = _rx_buffer_tail;
    if (_rx_buffer_head == tail) return -1;
    lost = rxLostAt[tail];
    if (lost) rxLostAt[tail] = 0;   // the ISR writes this slot only while it is free
    unsigned char c = _rx_buffer[tail];
    _rx_buffer_tail = (rx_buffer_index_t)((tail + 1) % SERIAL_RX_BUFFER_SIZE);
    return c;
  }
};

static WcSerial wcSerial(&UBRR0H, &UBRR0L, &UCSR0A, &UCSR0B, &UCSR0C, &UDR0);

// The ADC's conversions after the tick's start: the left motor's current, the right's,
// then the supply's, which runs without an interrupt until the next tick reads it.
// Interruptible (ISR_NOBLOCK): an encoder edge waits a few cycles, not the body's.
ISR(ADC_vect, ISR_NOBLOCK) {
  uint16_t count = ADC;
  if ((ADMUX & 7) == WC_PIN_CURRENT_L) {
    adcCurrentL = count;
    ADMUX = _BV(REFS0) | WC_PIN_CURRENT_R;
    ADCSRA |= _BV(ADSC);
  } else {
    adcCurrentR = count;
    ADMUX = _BV(REFS0) | WC_PIN_SUPPLY;
    ADCSRA = (uint8_t)((ADCSRA & ~_BV(ADIE)) | _BV(ADSC));
  }
}

ISR(USART0_RX_vect) { wcSerial.rxInterrupt(); }
ISR(USART0_UDRE_vect) { wcSerial.txInterrupt(); }

// ---------------------------------------------------------------------------
// Output lines: formatted with Arduino's Print into a fixed buffer and written
// whole, only when the TX ring has room, so loop() never blocks on the UART.
// ---------------------------------------------------------------------------
class LineBuffer : public Print {
 public:
  size_t write(uint8_t c) override {
    if (len_ >= sizeof(buf_)) return 0;
    buf_[len_++] = c;
    return 1;
  }
  using Print::write;

  // Decimal digits without division: Print::print divides by 10 once a digit (about
  // 600 cycles each, __udivmodsi4); repeated subtraction of powers of ten is about a
  // tenth of that. The same text as print(n).
  void printU32(uint32_t n) {
    static const uint32_t POW10[9] PROGMEM = {
      1000000000UL, 100000000UL, 10000000UL, 1000000UL, 100000UL, 10000UL, 1000UL, 100UL, 10UL,
    };
    bool started = false;
    for (uint8_t i = 0; i < 9; i++) {
      uint32_t p = pgm_read_dword(&POW10[i]);
      uint8_t digit = 0;
      while (n >= p) {
        n -= p;
        digit++;
      }
      if (digit != 0 || started) {
        write((uint8_t)('0' + digit));
        started = true;
      }
    }
    write((uint8_t)('0' + (uint8_t)n));
  }
  void printI32(int32_t n) {
    if (n < 0) {
      write('-');
      printU32((uint32_t)0 - (uint32_t)n);
    } else {
      printU32((uint32_t)n);
    }
  }

  // Queues the line if the output budget allows it: txCredit bytes, refilled at each
  // control tick at WC_TX_CREDIT_PER_MS per elapsed millisecond, less than the UART
  // drains, so the TX ring never fills and which lines go is decided by the budget
  // alone (the port computes the same). The ring check stays as a second guard.
  // After hello:4 the line is framed first (frameLine); the counter counts the lines
  // that go.
  void send() {
    if (linesFramed) frameLine();
    if (len_ > txCredit) {
      txDropped++;
    } else if (wcSerial.availableForWrite() < (int)len_) {
      txRingFull++;
    } else {
      txCredit -= len_;
      wcSerial.write(buf_, len_);
      if (linesFramed) lineCounter++;
    }
    len_ = 0;
  }

 private:
  // Protocol v4: the line's "\r\n" becomes "#NN*CCCC\r\n", NN the line counter and
  // CCCC the CRC-16/XMODEM of everything before the '*' (protocol/PROTOCOL.md).
  void frameLine() {
    len_ -= 2;
    write('#');
    writeHex(lineCounter, 2);
    uint16_t crc = 0;
    for (uint8_t i = 0; i < len_; i++) crc = _crc_xmodem_update(crc, buf_[i]);
    write('*');
    writeHex(crc, 4);
    write('\r');
    write('\n');
  }
  void writeHex(uint16_t v, uint8_t digits) {
    while (digits--) {
      uint8_t d = (v >> (4 * digits)) & 0xF;
      write((uint8_t)(d < 10 ? '0' + d : 'A' - 10 + d));
    }
  }

  uint8_t buf_[WC_TX_LINE_MAX];
  uint8_t len_ = 0;
};

static LineBuffer line;

static void sendEvent(const __FlashStringHelper* what) {
  line.print(F("EVT:"));
  line.println(what);
  line.send();
}

static const char F_STALL_L[] PROGMEM = "ENC_STALL_L";
static const char F_STALL_R[] PROGMEM = "ENC_STALL_R";
static const char F_REVERSED_L[] PROGMEM = "ENC_REVERSED_L";
static const char F_REVERSED_R[] PROGMEM = "ENC_REVERSED_R";
static const char F_IMPLAUSIBLE_L[] PROGMEM = "ENC_IMPLAUSIBLE_L";
static const char F_IMPLAUSIBLE_R[] PROGMEM = "ENC_IMPLAUSIBLE_R";
static const char F_DRIVER[] PROGMEM = "DRIVER_DEAD";
static const char F_MOTOR_L[] PROGMEM = "MOTOR_L";
static const char F_MOTOR_R[] PROGMEM = "MOTOR_R";
static const char F_BRAKE_OPEN[] PROGMEM = "BRAKE_OPEN";
static const char F_BRAKE_SHORT[] PROGMEM = "BRAKE_SHORT";
static const char F_OVERHEAT_L[] PROGMEM = "OVERHEAT_L";
static const char F_OVERHEAT_R[] PROGMEM = "OVERHEAT_R";
static const char F_UNDERVOLT[] PROGMEM = "UNDERVOLT";
static const char F_CURRENT_SENSE[] PROGMEM = "CURRENT_SENSE";
#define FAULT_COUNT 15
static const char* const FAULT_NAMES[FAULT_COUNT] = {
  F_STALL_L, F_STALL_R, F_REVERSED_L, F_REVERSED_R, F_IMPLAUSIBLE_L, F_IMPLAUSIBLE_R, F_DRIVER,
  F_MOTOR_L, F_MOTOR_R, F_BRAKE_OPEN, F_BRAKE_SHORT, F_OVERHEAT_L, F_OVERHEAT_R, F_UNDERVOLT,
  F_CURRENT_SENSE,
};

// One EVT:FAULT,<name> line per fault bit set.
static void sendFaultEvents(uint16_t faults) {
  for (uint8_t i = 0; i < FAULT_COUNT; i++) {
    if (faults & (1u << i)) {
      line.print(F("EVT:FAULT,"));
      line.println((const __FlashStringHelper*)FAULT_NAMES[i]);
      line.send();
    }
  }
}

// ---------------------------------------------------------------------------
// Control law
// ---------------------------------------------------------------------------
// The PID's output within lo..hi (+-WC_PID_OUT_MAX, or a motor's rolled-back current
// limit: pidBounds), the integral back-calculated to whichever bound binds.
static float computePID(float setpoint, float measurement, float& integral, float& prevMeas,
                        float kp, float ki, float kd, float dt, float lo, float hi) {
  float error = setpoint - measurement;
  integral += error * dt;
  float limit = WC_PID_OUT_MAX / ki;
  integral = constrain(integral, -limit, limit);
  float derivative = -(measurement - prevMeas) / dt;   // on measurement: no setpoint kick
  float output = kp * error + ki * integral + kd * derivative;
  float clamped = constrain(output, lo, hi);
  if (output != clamped) {
    integral = (clamped - kp * error - kd * derivative) / ki;   // back-calculation
    // Never past zero: a P term beyond the clamp on its own would wind the integral
    // against the saturation, and the wheel would be driven backward once the error fell.
    if ((integral > 0.0f) != (clamped > 0.0f)) integral = 0.0f;
  }
  prevMeas = measurement;
  return clamped;
}

// ---------------------------------------------------------------------------
// The motors' heat (docs/safety.md, "Motor heat")
// ---------------------------------------------------------------------------
// Watts of copper loss of a motor driven at pwm one way (dir HIGH: the way vel counts
// positive) while its wheel turns at vel: the effort (the duty less what the back-EMF
// takes, WC_THERMAL_EMF a rad/s, within the driver's current limit) squared,
// WC_THERMAL_LOSS a duty squared.
// From what it commands, less what it measures: the estimate does not read the current
// senses (it came before them; docs/safety.md, "Motor heat").
static float windingLoss(uint8_t pwm, uint8_t dir, float vel) {
  float duty = dir == HIGH ? (float)pwm : -(float)pwm;
  float effort = duty - WC_THERMAL_EMF * vel;
  if (effort > WC_FAULT_EFFORT_MAX) {
    effort = WC_FAULT_EFFORT_MAX;
  } else if (effort < -WC_FAULT_EFFORT_MAX) {
    effort = -WC_FAULT_EFFORT_MAX;
  }
  return effort * effort * WC_THERMAL_LOSS;
}

// A winding's estimate dt seconds on, loss watts in: one thermal mass cooled through
// WC_THERMAL_RESISTANCE toward WC_THERMAL_AMBIENT.
static float windingStep(float temp, float loss, float dt) {
  float cool = (temp - WC_THERMAL_AMBIENT) / WC_THERMAL_RESISTANCE;
  return temp + dt * (loss - cool) / WC_THERMAL_CAPACITY;
}

// Both estimates a tick on, from the duty that drove the interval that ended and the
// speed at its end; the rollback's start and end, their events pending.
static void updateThermal(float dt) {
  windingTempL = windingStep(windingTempL, windingLoss(pwmL, dirL, filtVelL), dt);
  windingTempR = windingStep(windingTempR, windingLoss(pwmR, dirR, filtVelR), dt);
  float hot = windingTempL > windingTempR ? windingTempL : windingTempR;
  if (!thermalRollback && hot > WC_THERMAL_ROLLBACK_TEMP) {
    thermalRollback = 1;
    thermalPending |= 1;
  } else if (thermalRollback && hot < WC_THERMAL_ROLLBACK_TEMP - WC_THERMAL_HYSTERESIS) {
    thermalRollback = 0;
    thermalPending |= 2;
  }
}

// How far the rollback has gone at temp: 0 up to WC_THERMAL_ROLLBACK_TEMP, 1 from
// WC_THERMAL_CUTOFF_TEMP, linear between.
static float rollbackOf(float temp) {
  if (temp <= WC_THERMAL_ROLLBACK_TEMP) return 0.0f;
  float k = (temp - WC_THERMAL_ROLLBACK_TEMP) / (WC_THERMAL_CUTOFF_TEMP - WC_THERMAL_ROLLBACK_TEMP);
  return k >= 1.0f ? 1.0f : k;
}

// The top wheel speed the hotter winding allows, as a share of max_wheel (1: no cap).
static float thermalShare() {
  float hot = windingTempL > windingTempR ? windingTempL : windingTempR;
  return 1.0f - rollbackOf(hot) * (1.0f - WC_THERMAL_SHARE_MIN);
}

// The PID output's bounds for a motor whose winding is at temp, its wheel at vel: past
// the rollback's start an output that drives (the way the wheel turns, or from a
// standstill) asks no more effort than the rolled-back current limit; braking is free.
static void pidBounds(float temp, float vel, float& lo, float& hi) {
  lo = -WC_PID_OUT_MAX;
  hi = WC_PID_OUT_MAX;
  float k = rollbackOf(temp);
  if (k == 0.0f) return;
  float cap = WC_FAULT_EFFORT_MAX - k * (WC_FAULT_EFFORT_MAX - WC_THERMAL_EFFORT_MIN);
  float emf = WC_THERMAL_EMF * vel;
  if (vel >= 0.0f) {
    hi = (emf + cap) / WC_PWM_SCALE;
    if (hi > WC_PID_OUT_MAX) hi = WC_PID_OUT_MAX;
  }
  if (vel <= 0.0f) {
    lo = (emf - cap) / WC_PWM_SCALE;
    if (lo < -WC_PID_OUT_MAX) lo = -WC_PID_OUT_MAX;
  }
}

// The windings at WC_THERMAL_CUTOFF_TEMP or more: their faults.
static uint16_t thermalFault() {
  return (windingTempL >= WC_THERMAL_CUTOFF_TEMP ? FAULT_OVERHEAT_L : 0) |
         (windingTempR >= WC_THERMAL_CUTOFF_TEMP ? FAULT_OVERHEAT_R : 0);
}

// The filtered supply a tick on, from supplyTick (the first reading stands as it is);
// the low-battery rollback's start and end, their events pending.
static void updateSupply() {
  float volts = (float)supplyTick * WC_SUPPLY_VOLTS_PER_COUNT;
  if (supplyVolts == 0.0f) supplyVolts = volts;
  else supplyVolts = supplyVolts + WC_SUPPLY_FILTER * (volts - supplyVolts);
  if (!batteryLow && supplyVolts < WC_BATTERY_LOW_V) {
    batteryLow = 1;
    batteryPending |= 1;
  } else if (batteryLow && supplyVolts > WC_BATTERY_LOW_V + WC_BATTERY_HYSTERESIS) {
    batteryLow = 0;
    batteryPending |= 2;
  }
}

// The top wheel speed the filtered supply allows, as a share of max_wheel: 1 from
// WC_BATTERY_LOW_V up, WC_BATTERY_SHARE_MIN at WC_BATTERY_CUTOFF_V and below.
static float batteryShare() {
  if (supplyVolts >= WC_BATTERY_LOW_V) return 1.0f;
  float k = (WC_BATTERY_LOW_V - supplyVolts) / (WC_BATTERY_LOW_V - WC_BATTERY_CUTOFF_V);
  if (k > 1.0f) k = 1.0f;
  return 1.0f - k * (1.0f - WC_BATTERY_SHARE_MIN);
}

// The filtered supply below WC_BATTERY_CUTOFF_V (a sense wire cut reads 0 V): its fault.
static uint16_t batteryFault() {
  return supplyVolts < WC_BATTERY_CUTOFF_V ? FAULT_UNDERVOLT : 0;
}

// The motors' currents (docs/safety.md, "Stall timeout")

// The current an ADC count of a current sense reads, A: positive drives the wheel
// forward (DIR HIGH), negative backward (or brakes a wheel driven forward).
static float senseAmps(uint16_t count) {
  return (float)((int16_t)count - WC_CURRENT_ZERO_COUNTS) * WC_CURRENT_AMPS_PER_COUNT;
}

// A current sense reading beyond WC_CURRENT_SENSE_MAX (its output cut or shorted): its fault.
static uint16_t currentSenseFault() {
  return (fabs(senseAmps(currentTickL)) > WC_CURRENT_SENSE_MAX || fabs(senseAmps(currentTickR)) > WC_CURRENT_SENSE_MAX)
             ? FAULT_CURRENT_SENSE
             : 0;
}

static float rampToward(float current, float target, float maxChange) {
  float diff = target - current;
  if (fabs(diff) <= maxChange) return target;
  return current + (diff > 0.0f ? maxChange : -maxChange);
}

// The tremor damping (docs/safety.md, "Drive profiles"): in PPM mode (the joystick) with
// tremorDamping set, each goal moves (1 - tremorDamping) of the way from where it was to
// its target, a first-order low-pass of the stick at the tick's 20 Hz that takes a hand's
// tremor out of the motion; otherwise, and whenever both targets are 0 (a stop is never
// damped), the goals are the targets. The host's paths (WHEEL, CMDVEL) are not a hand's.
static void dampedTargets(float& goalL, float& goalR) {
  if (mode != WC_MODE_PPM || tremorDamping == 0.0f || (targetL == 0.0f && targetR == 0.0f)) {
    dampedL = targetL;
    dampedR = targetR;
  } else {
    float gain = 1.0f - tremorDamping;
    dampedL = dampedL + gain * (targetL - dampedL);
    dampedR = dampedR + gain * (targetR - dampedR);
  }
  goalL = dampedL;
  goalR = dampedR;
}

// The wheel goals within the drive limits: the chair's speed (the wheels' mean at the
// rim) within fwdSpeed forward and revSpeed back, its turn rate within turnSpeed, less
// as the speed nears its top (turnAtSpeed of it there). Goals within them pass as they are.
static void driveCaps(float& goalL, float& goalR) {
  float speed = (goalR + goalL) * 0.5f * WC_WHEEL_RADIUS;
  float turn = (goalR - goalL) * WC_WHEEL_RADIUS / WC_WHEELBASE;
  float top = speed >= 0.0f ? fwdSpeed : revSpeed;
  float held = speed;
  if (speed > fwdSpeed) held = fwdSpeed;
  else if (speed < -revSpeed) held = -revSpeed;
  float cap = turnSpeed * (1.0f - (1.0f - turnAtSpeed) * (fabs(held) / top));
  float turned = turn;
  if (turn > cap) turned = cap;
  else if (turn < -cap) turned = -cap;
  if (held == speed && turned == turn) return;
  float half = turned * (WC_WHEELBASE * 0.5f);
  goalL = (held - half) / WC_WHEEL_RADIUS;
  goalR = (held + half) / WC_WHEEL_RADIUS;
}

// rad/s^2 a wheel's setpoint may move toward its goal: driveAccel speeding up (away
// from zero), driveDecel otherwise, within maxAccel.
static float wheelRate(float setpoint, float goal) {
  bool speedingUp = (goal > setpoint && setpoint >= 0.0f) || (goal < setpoint && setpoint <= 0.0f);
  float rate = (speedingUp ? driveAccel : driveDecel) / WC_WHEEL_RADIUS;
  return maxAccel < rate ? maxAccel : rate;
}

// Both setpoints a tick toward their goals: the emergency ramp at estopDecel; else each
// wheel at its wheelRate, the wheels' half difference moving at most turnAccel x half the
// wheelbase / WHEEL_RADIUS a second (their mean kept).
static void rampSetpoints(float goalL, float goalR, float dt) {
  if (emergencyStop) {
    float step = estopDecel * dt;
    setpointL = rampToward(setpointL, goalL, step);
    setpointR = rampToward(setpointR, goalR, step);
    return;
  }
  float newL = rampToward(setpointL, goalL, wheelRate(setpointL, goalL) * dt);
  float newR = rampToward(setpointR, goalR, wheelRate(setpointR, goalR) * dt);
  float limit = turnAccel * (WC_WHEELBASE * 0.5f) / WC_WHEEL_RADIUS * dt;
  float was = (setpointR - setpointL) * 0.5f;
  float change = (newR - newL) * 0.5f - was;
  if (change > limit || change < -limit) {
    float mid = (newR + newL) * 0.5f;
    float half = was + (change > 0.0f ? limit : -limit);
    newL = mid - half;
    newR = mid + half;
  }
  setpointL = newL;
  setpointR = newR;
}

static bool needsPivot(float travel, float prevTravel) {
  return (prevTravel > WC_PIVOT_THRESHOLD && travel < -WC_PIVOT_THRESHOLD) ||
         (prevTravel < -WC_PIVOT_THRESHOLD && travel > WC_PIVOT_THRESHOLD);
}

static void setMotor(uint8_t pwmPin, uint8_t dirPin, float output, uint8_t& pwm, uint8_t& dir) {
  dir = output >= 0.0f ? HIGH : LOW;
  digitalWrite(dirPin, dir);
  pwm = (uint8_t)(int)(fabs(output) * WC_PWM_SCALE);
  analogWrite(pwmPin, pwm);
}

// The hold's reference follows a wheel that still slows (a step of the same sign, no
// larger than the last), then stays, and is never more than WC_ROLLAWAY_COUNTS + 1 behind
// the wheel: a chair pushed farther is braked, not driven back. Returns the wheel's count
// error from it.
static int32_t holdError(int32_t count, int32_t delta, int32_t& ref, int32_t& step) {
  if (step != 0) {
    bool slowing = delta != 0 && (delta > 0) == (step > 0) &&
                   (delta > 0 ? delta <= step : delta >= step);
    if (slowing) {
      ref = count;
      step = delta;
    } else {
      step = 0;
    }
  }
  int32_t error = (int32_t)((uint32_t)count - (uint32_t)ref);
  if (error > WC_ROLLAWAY_COUNTS + 1 || error < -(WC_ROLLAWAY_COUNTS + 1)) {
    error = error > 0 ? WC_ROLLAWAY_COUNTS + 1 : -(WC_ROLLAWAY_COUNTS + 1);
    ref = (int32_t)((uint32_t)count - (uint32_t)error);
  }
  return error;
}

// The hold's duty for a count error: WC_HOLD_GAIN per count beyond WC_HOLD_DEADBAND_COUNTS,
// at most WC_HOLD_PWM_MAX; after a rollaway, WC_HOLD_PWM_MAX beyond the deadband.
static uint8_t holdDuty(int32_t error) {
  uint32_t size = error < 0 ? (uint32_t)0 - (uint32_t)error : (uint32_t)error;
  if (size <= WC_HOLD_DEADBAND_COUNTS) return 0;
  uint32_t over = size - WC_HOLD_DEADBAND_COUNTS;
  if (holdRollaway || over >= (uint32_t)WC_HOLD_PWM_MAX / WC_HOLD_GAIN) return WC_HOLD_PWM_MAX;
  return (uint8_t)(over * WC_HOLD_GAIN);
}

// Drives one held wheel against its count error: holdDuty() toward the reference,
// aheadDir being the DIR level that turns the wheel back when its count has run ahead
// (LOW on the right, whose counts rise forward; HIGH on the mirrored left). At duty 0,
// DIR HIGH: what setMotor() writes for an output of 0.
// Push mode (the brake released by hand): a wheel whose encoder is trusted, slower than
// WC_PUSH_SPEED, at the duty its back-EMF takes the way it turns (no current: no torque,
// the chair pushed as if freewheeling); faster, or not trusted, at duty 0 (the motor
// shorted: it brakes the wheel).
static void pushMotor(uint8_t pwmPin, uint8_t dirPin, bool trusted, float vel, uint8_t& pwm, uint8_t& dir) {
  float speed = fabs(vel);
  if (!trusted || speed > WC_PUSH_SPEED) {
    pwm = 0;
    dir = HIGH;
  } else {
    pwm = (uint8_t)(int)(speed * WC_FAULT_EFFORT_EMF);
    dir = vel >= 0.0f ? HIGH : LOW;
  }
  digitalWrite(dirPin, dir);
  analogWrite(pwmPin, pwm);
}

static void holdMotor(uint8_t pwmPin, uint8_t dirPin, int32_t error, uint8_t aheadDir,
                      uint8_t& pwm, uint8_t& dir) {
  pwm = holdDuty(error);
  if (pwm == 0) {
    dir = HIGH;
  } else {
    dir = error > 0 ? aheadDir : (aheadDir == HIGH ? LOW : HIGH);
  }
  digitalWrite(dirPin, dir);
  analogWrite(pwmPin, pwm);
}

// Targets to zero; the ramp brings the setpoints down at the emergency rate and the
// PID brakes the wheels along it. Its integrators start from zero: what they held to
// keep the chair rolling would push against the brake. What they held, and the
// setpoints then, are kept for a command that drives on during the ramp
// (resumedIntegral).
static void emergencyHalt() {
  if (!emergencyStop) {
    haltIntegralL = integralL;
    haltIntegralR = integralR;
    haltSetpointL = setpointL;
    haltSetpointR = setpointR;
    integralL = integralR = 0.0f;
  }
  targetL = targetR = 0.0f;
  pivotPhase = PIVOT_NONE;
  pivotTicksLeft = 0;
  lastTravel = 0.0f;
  emergencyStop = true;
}

// Motion needs a neutral command first (needNeutral): a new wait, or the one under way
// goes on (its refusal already announced, its fault count running).
static void requireNeutral() {
  if (!needNeutral) {
    notNeutralSent = false;
    notNeutralTicks = 0;
    neutralFault = false;
  }
  needNeutral = true;
  neutralSeen = false;
}

// The inhibit inputs engaged (debounced, or latched).
static uint8_t inhibitEngaged() { return inhibitStable | inhibitLatched; }

// One input's debounce: the read level must differ from the debounced one for
// WC_INHIBIT_DEBOUNCE_TICKS ticks in a row.
static void debounceInhibit(uint8_t bit, uint8_t& count) {
  if ((inhibitTick & bit) == (inhibitStable & bit)) {
    count = 0;
  } else if (++count >= WC_INHIBIT_DEBOUNCE_TICKS) {
    inhibitStable ^= bit;
    count = 0;
  }
}

// The tick's inhibit inputs: debounced and latched. An input that engages with speed 0
// stops the chair along the normal ramp, as a stop command; so does one that is released
// (the command from before it no longer drives), which asks for neutral too. The events
// (EVT:INHIBIT,<n>,<1|0>) go out from this tick on, one a tick.
static void updateInhibits() {
  uint8_t before = inhibitOn;   // a reset may have ended a latch since
  debounceInhibit(1, inhibitCountL);
  debounceInhibit(2, inhibitCountR);
  debounceInhibit(INHIBIT_PUSH, inhibitCountP);
  inhibitLatched |= inhibitStable & INHIBIT_LATCH_MASK;
  uint8_t after = inhibitEngaged();
  inhibitOn = after;
  uint8_t on = after & (uint8_t)~before, off = before & (uint8_t)~after;
  if ((on & INHIBIT_STOP_MASK) || off) {
    targetL = targetR = 0.0f;     // the normal ramp down, as a stop command
    pivotPhase = PIVOT_NONE;
    pivotTicksLeft = 0;
    lastTravel = 0.0f;
  }
  if (off) requireNeutral();
  inhibitPending |= (on & 1) | (off & 1) << 1 | (on & 2) << 1 | (off & 2) << 2 |
                    (on & INHIBIT_PUSH) << 2 | (off & INHIBIT_PUSH) << 3;
}

// The top wheel speed the engaged inputs allow, as a share of max_wheel (1: no cap).
static float inhibitShare() {
  uint8_t engaged = inhibitEngaged();
  float share = 1.0f;
  if ((engaged & 1) && WC_INHIBIT_1_SPEED < share) share = WC_INHIBIT_1_SPEED;
  if ((engaged & 2) && WC_INHIBIT_2_SPEED < share) share = WC_INHIBIT_2_SPEED;
  return share;
}

// A setpoint no farther its way than the wheel's measured speed, and never past zero: a
// PID that runs on it can only brake the wheel.
static float brakingSetpoint(float setpoint, float measured) {
  if (setpoint > 0.0f) return measured <= 0.0f ? 0.0f : (measured < setpoint ? measured : setpoint);
  if (setpoint < 0.0f) return measured >= 0.0f ? 0.0f : (measured > setpoint ? measured : setpoint);
  return setpoint;
}

// An output that brakes the wheel (against its speed over the last tick), else 0: the
// derivative of a wheel the brake stops at once would kick it forward.
static float brakingOutput(float output, float measured) {
  return (output > 0.0f && measured < 0.0f) || (output < 0.0f && measured > 0.0f) ? output : 0.0f;
}

// A brake coil fault (brake_fitted 1): the brake driver's status LOW for
// WC_BRAKE_STATUS_TICKS ticks in a row. The switch flags an open load while off (the
// brake engaged) and an overload while on (released), so the pin says which.
static uint16_t brakeCoilFault() {
  if (!brakeFitted || !brakeStatusTick) {
    brakeStatusTicks = 0;
    return 0;
  }
  if (++brakeStatusTicks < WC_BRAKE_STATUS_TICKS) return 0;
  brakeStatusTicks = 0;
  return brakeReleased ? FAULT_BRAKE_SHORT : FAULT_BRAKE_OPEN;
}

// The parking brake's phase for this tick (brake_fitted 1), given whether the chair
// parks; sets brakeReleased, the pin's level. Parked WC_BRAKE_ACTIVE_TICKS, or at once on
// a fault, the pin goes LOW; WC_BRAKE_ENGAGE_TICKS later the brake holds. A motion asked
// for (not parked, no fault) first drives the hold WC_BRAKE_PRELOAD_TICKS, then sets the
// pin HIGH and waits WC_BRAKE_RELEASE_TICKS. A change of the pin starts the coil's
// status count again (its two reads must see one level). Returns whether the chair stays
// parked: as asked, or under the hold while the brake lets go.
static bool brakeStep(bool park) {
  bool drive = !park && faultFlags == 0;
  bool was = brakeReleased;
  switch (brakePhase) {
    case BRAKE_RELEASED:
      if (faultFlags != 0 || (park && ++brakeTicks >= WC_BRAKE_ACTIVE_TICKS)) {
        brakePhase = BRAKE_ENGAGING;
        brakeTicks = 0;
      } else if (!park) {
        brakeTicks = 0;
      }
      break;
    case BRAKE_ENGAGING:
      if (drive) {   // the hold (or the PID) still drives: let go at once
        brakePhase = BRAKE_RELEASING;
        brakeTicks = 0;
      } else if (++brakeTicks >= WC_BRAKE_ENGAGE_TICKS) {
        brakePhase = BRAKE_ENGAGED;
      }
      break;
    case BRAKE_ENGAGED:
      if (drive) {
        brakePhase = BRAKE_PRELOAD;
        brakeTicks = 0;
      }
      break;
    case BRAKE_PRELOAD:
      if (!drive) {
        brakePhase = BRAKE_ENGAGED;
      } else if (++brakeTicks >= WC_BRAKE_PRELOAD_TICKS) {
        brakePhase = BRAKE_RELEASING;
        brakeTicks = 0;
      }
      break;
    default:   // BRAKE_RELEASING
      if (faultFlags != 0) {
        brakePhase = BRAKE_ENGAGING;
        brakeTicks = 0;
      } else if (!drive || ++brakeTicks >= WC_BRAKE_RELEASE_TICKS) {
        brakePhase = BRAKE_RELEASED;
        brakeTicks = 0;
      }
      break;
  }
  brakeReleased = brakePhase == BRAKE_RELEASING || brakePhase == BRAKE_RELEASED;
  if (brakeReleased != was) brakeStatusTicks = 0;
  return park || (drive && brakePhase != BRAKE_RELEASED);
}

// What one wheel's encoder showed over the interval that just ended, driven at
// appliedPwm in direction appliedDir (the last tick's) with setpoint (the last tick's):
// WHEEL_OK; WHEEL_SUSPECT (no count although driven toward a setpoint, or measured
// against the setpoint: the PID must not push harder on it this tick); or a fault:
// stalled or cut, reversed, implausible (storm or illegal transitions). Braking (a duty
// against the setpoint, or toward a zero setpoint) ends with no count: not a stall. A
// wheel turning round (what the PID last ran on, prevMeasured, against the setpoint)
// stands while its duty builds to break it away: its stall takes
// WC_FAULT_STALL_TICKS_TURNING ticks.
// Measured against the setpoint does not count while the wheel came
// WC_FAULT_REVERSE_APPROACH closer to it since prevMeasured (what the PID last ran on):
// a healthy wheel lagging a reversal of its setpoint slows toward it; a reversed encoder
// shows the wheel moving away, or no closer. Running away (runsAway) counts one up a
// tick; driving, any other tick one down (to 0), holding, to 0: WC_FAULT_RUNAWAY_TICKS is
// a reversed encoder too.
#define WHEEL_OK 0
#define WHEEL_SUSPECT 1
#define WHEEL_STALLED 2
#define WHEEL_REVERSED 3
#define WHEEL_IMPLAUSIBLE 4
#define WHEEL_NO_EFFECT 5
// Effort without progress: toward a steady setpoint the duty has stayed
// WC_FAULT_EFFORT_PWM above its lowest (or at full duty, which can rise no more, with the
// other wheel's duty, otherPwm, WC_FAULT_EFFORT_PWM or less below it: the chair at its top
// speed, not the outer wheel of a turn) for WC_FAULT_EFFORT_TICKS ticks in a row while the
// wheel gained no speed, turns slower than WC_FAULT_EFFORT_SHORTFALL_MOTOR of its setpoint,
// and leads the other wheel (other: its measured speed) by less than WC_FAULT_EFFORT_LEAD
// its way (a dead motor's wheel is only dragged along, and trails the wheel that drags it,
// or stands when that one turns against it). A new setpoint, a duty away from it, any
// gain in speed, or the wheel turning faster than its setpoint starts over: a wheel being
// slowed to its setpoint (a sharp change of course) runs on a low duty, and its return to
// the duty that holds the setpoint is no effort without progress. While the other wheel's
// own motor drives it on beyond its setpoint (otherOverruns: overruns), the chair is not
// following the command, and this wheel's effort goes into turning it: the count starts
// over. (A partner carried beyond its setpoint by a slope is braked, not driven: it stops
// nothing.) Whose load it is, one motor's or the chair's, is the caller's: effortLeads.
static bool noEffect(uint8_t appliedPwm, uint8_t appliedDir, float setpoint, float measured,
                     float other, uint8_t otherPwm, bool otherOverruns, uint8_t& effortPwm, float& effortSpeed,
                     float& effortSetpoint, uint8_t& effortTicks) {
  float progress = setpoint > 0.0f ? measured : -measured;
  bool toward = setpoint != 0.0f && (appliedDir == HIGH) == (setpoint > 0.0f);
  if (!toward || setpoint != effortSetpoint || progress > effortSpeed || progress > fabs(setpoint)) {
    effortSetpoint = setpoint;
    effortSpeed = progress;
    effortPwm = appliedPwm;
    effortTicks = 0;
    return false;
  }
  if (appliedPwm < effortPwm) effortPwm = appliedPwm;
  bool shortfall = fabs(measured) < WC_FAULT_EFFORT_SHORTFALL_MOTOR * fabs(setpoint);
  float otherProgress = setpoint > 0.0f ? other : -other;
  bool trails = progress < (otherProgress > 0.0f ? otherProgress : 0.0f) + WC_FAULT_EFFORT_LEAD;
  bool rose = appliedPwm >= effortPwm + WC_FAULT_EFFORT_PWM ||
              (appliedPwm == 255 && otherPwm + WC_FAULT_EFFORT_PWM >= 255);
  effortTicks = shortfall && trails && !otherOverruns && rose ? effortTicks + 1 : 0;
  return effortTicks >= WC_FAULT_EFFORT_TICKS;
}

// A wheel's effort: its duty toward its setpoint (against it, negative) less what the
// back-EMF of its speed that way takes (WC_FAULT_EFFORT_EMF per rad/s), the share of the
// duty that drives current, so torque (negative: braking); within WC_FAULT_EFFORT_MAX
// either way, the driver's current limit, past which more gives no more torque. 0
// without a setpoint.
static float effortOf(uint8_t appliedPwm, uint8_t appliedDir, float setpoint, float measured) {
  if (setpoint == 0.0f) return 0.0f;
  bool forward = setpoint > 0.0f;
  float duty = (appliedDir == HIGH) == forward ? (float)appliedPwm : -(float)appliedPwm;
  float progress = forward ? measured : -measured;
  float effort = duty - WC_FAULT_EFFORT_EMF * progress;
  if (effort <= -WC_FAULT_EFFORT_MAX) return -WC_FAULT_EFFORT_MAX;
  return effort < WC_FAULT_EFFORT_MAX ? effort : WC_FAULT_EFFORT_MAX;
}

// One motor's fault, not the chair's load: the wheel's effort (effortOf) leads the other
// wheel's by WC_FAULT_EFFORT_LEAD_PWM or more, the other not held back by its own
// setpoint; or it should brake at the current limit (its duty far below its back-EMF) while the other brakes WC_FAULT_EFFORT_LEAD_PWM less,
// and yet its PID winds its duty up without a gain (a dead wheel carried along by the
// chair down a grade: a healthy one would brake, and slow, harder than its partner); or,
// both at the current limit (WC_FAULT_EFFORT_MAX) and the other short of its setpoint,
// it turns WC_FAULT_EFFORT_LAG slower than the other, each its own way, beyond what the
// setpoints ask (a setpoint asking this wheel for more than the other is no excuse: at
// the limit neither gets its setpoint). A dead motor's PID winds its duty up while the partner carries the
// chair at its own, and where both ask more than the current limit gives, equal torques
// would keep the wheels together: a wheel left behind is one without torque. A grade, a
// kerb or a ramp's edge loads both wheels alike, and both duties rise together,
// whichever wheel's count ran first.
static bool effortLeads(uint8_t appliedPwm, uint8_t appliedDir, float setpoint, float measured,
                        uint8_t otherPwm, uint8_t otherDir, float otherSetpoint, float other) {
  float effort = effortOf(appliedPwm, appliedDir, setpoint, measured);
  float otherEffort = effortOf(otherPwm, otherDir, otherSetpoint, other);
  float otherProgress = otherSetpoint > 0.0f ? other : -other;
  // A partner braking down to its setpoint works as hard as one driving: its braking
  // slows the chair that this wheel drives.
  bool brakingDown = otherEffort < 0.0f && otherProgress > fabs(otherSetpoint);
  float otherWork = brakingDown ? -otherEffort : otherEffort;
  // A partner held back by its own setpoint, WC_FAULT_EFFORT_OVERRUN or more behind it
  // this wheel's way (a spin, a sharp turn, a stop), holds the chair back: the chair
  // does not follow this wheel's command, and its effort goes into that.
  float heldBack = setpoint > 0.0f ? other - otherSetpoint : otherSetpoint - other;
  // A partner braking below the current limit while short of its setpoint by
  // WC_FAULT_EFFORT_SHORTFALL of it and WC_FAULT_EFFORT_OVERRUN (its PID unwinding after
  // a descent or a cut of its setpoint) slows the chair of its own accord; one braking at
  // the limit may be holding a dead wheel's chair.
  bool brakingShort = -WC_FAULT_EFFORT_MAX < otherEffort && otherEffort < 0.0f &&
                      otherProgress < WC_FAULT_EFFORT_SHORTFALL * fabs(otherSetpoint) &&
                      otherProgress < fabs(otherSetpoint) - WC_FAULT_EFFORT_OVERRUN;
  if (heldBack < WC_FAULT_EFFORT_OVERRUN && !brakingShort &&
      effort >= otherWork + WC_FAULT_EFFORT_LEAD_PWM) {
    return true;
  }
  if (effort <= -WC_FAULT_EFFORT_MAX && otherEffort >= effort + WC_FAULT_EFFORT_LEAD_PWM) return true;
  if (effort < WC_FAULT_EFFORT_MAX || otherEffort < WC_FAULT_EFFORT_MAX) return false;
  float progress = setpoint > 0.0f ? measured : -measured;
  if (otherProgress >= fabs(otherSetpoint)) return false;
  float asked = fabs(otherSetpoint) - fabs(setpoint);
  return (otherProgress - progress) - (asked > 0.0f ? asked : 0.0f) >= WC_FAULT_EFFORT_LAG;
}

// Driven on beyond its setpoint: a duty toward the setpoint (not braking) while the wheel
// turns WC_FAULT_EFFORT_OVERRUN or more beyond it that way.
static bool overruns(uint8_t appliedPwm, uint8_t appliedDir, float setpoint, float measured) {
  float progress = setpoint > 0.0f ? measured : -measured;
  return setpoint != 0.0f && appliedPwm > 0 && (appliedDir == HIGH) == (setpoint > 0.0f) &&
         progress > fabs(setpoint) + WC_FAULT_EFFORT_OVERRUN;
}

// Running away: braked at WC_FAULT_RUNAWAY_PWM or more against its measured motion,
// WC_FAULT_REVERSE_SPEED or more beyond its setpoint that way, and WC_FAULT_RUNAWAY_GAIN
// or more faster than prevMeasured (what the PID last ran on). A braked wheel slows unless
// something pushes it; one whose encoder counts against the motion speeds up, the more
// the harder the PID pushes (positive feedback). That is a reversed encoder whose reading
// flipped sign while its setpoint crossed zero, which the "against" rule never sees.
static bool runsAway(uint8_t appliedPwm, uint8_t appliedDir, float setpoint, float measured,
                     float prevMeasured) {
  bool forward = measured > 0.0f;
  float beyond = forward ? measured - setpoint : setpoint - measured;
  return appliedPwm >= WC_FAULT_RUNAWAY_PWM && (appliedDir == HIGH) != forward &&
         fabs(measured) >= WC_FAULT_REVERSE_SPEED && beyond >= WC_FAULT_REVERSE_SPEED &&
         fabs(measured) - fabs(prevMeasured) >= WC_FAULT_RUNAWAY_GAIN;
}

// Overspeeding: moving the way of its setpoint (or with none), WC_OVERSPEED_MARGIN or
// more beyond it and beyond its target (faster than commanded, not a ramp behind), and
// braked at WC_OVERSPEED_PWM or more against the motion. (The duty says little of the
// braking: at speed the driver's current limit binds at a low duty.) Whether gravity
// beats the motors is the speed gained over the run of such ticks (overspeedRun).
static bool overspeeding(uint8_t appliedPwm, uint8_t appliedDir, float setpoint, float target,
                         float measured) {
  bool forward = measured > 0.0f;
  float beyond = forward ? measured - setpoint : setpoint - measured;
  float beyondTarget = forward ? measured - target : target - measured;
  bool along = setpoint == 0.0f || (setpoint > 0.0f) == forward;
  return along && appliedPwm >= WC_OVERSPEED_PWM && (appliedDir == HIGH) != forward &&
         beyond >= WC_OVERSPEED_MARGIN && beyondTarget >= WC_OVERSPEED_MARGIN;
}

// Counts a run of overspeeding ticks (ticks, wrapping at 256), from the speed the PID ran
// on before its first (from); true once the run is WC_OVERSPEED_TICKS long and the wheel
// WC_OVERSPEED_GAIN faster than that: gravity beats the motors. Within its rated grade a
// braked chair slows, however slowly; over a run the tick-to-tick jitter of the measured
// speed (about 0.2 rad/s at top speed) does not add up.
static bool overspeedRun(bool over, float measured, float prevMeasured, uint8_t& ticks, float& from) {
  if (!over) {
    ticks = 0;
    return false;
  }
  if (ticks == 0) from = fabs(prevMeasured);
  ticks++;
  return ticks >= WC_OVERSPEED_TICKS && fabs(measured) - from >= WC_OVERSPEED_GAIN;
}

// Straining: driven at WC_GRADE_PWM or more toward a setpoint it runs short of (slower
// than WC_FAULT_EFFORT_SHORTFALL of it that way, or against it).
static bool straining(uint8_t appliedPwm, uint8_t appliedDir, float setpoint, float measured) {
  float progress = setpoint > 0.0f ? measured : -measured;
  return setpoint != 0.0f && (appliedDir == HIGH) == (setpoint > 0.0f) &&
         appliedPwm >= WC_GRADE_PWM && progress < WC_FAULT_EFFORT_SHORTFALL * fabs(setpoint);
}

// Spinning about this wheel: a spin asked (the partner's setpoint the other way from this
// wheel's) and the partner standing or turning its own setpoint's way: the chair pivots
// about this wheel, as a spin on a grade does when the wheel that would turn the chair
// uphill stands at its current limit. A partner turning this wheel's way would show the
// chair moving, and this wheel with it.
static bool spinsAbout(float setpoint, float otherSetpoint, float other) {
  if (setpoint == 0.0f || otherSetpoint == 0.0f || (otherSetpoint > 0.0f) == (setpoint > 0.0f)) return false;
  float along = otherSetpoint > 0.0f ? other : -other;
  return along >= 0.0f;
}

// A wheel held at its current limit: the wheel standing (WC_STALL_CREEP_COUNTS this tick
// at most, either way) beside a partner that stands too or pivots the chair about it
// (spinsAbout), driven toward its setpoint at WC_FAULT_STALL_PWM_STANDING or more, its
// motor drawing WC_STALL_CURRENT or more the way it is driven (a braking current, a wheel
// pushed faster than its duty turns it, is not). Not an encoder fault but the stall
// timeout's: its PID runs within WC_STALL_HELD_OUTPUT (heldBounds), so that a current
// that high means the wheel turns at most (duty - its current's share) / back-EMF a
// rad/s: 0.5. A cut encoder's wheel that turns faster draws less, and one beside a
// partner that counts its way (a chair crawling up a grade at its limit) is a stalled
// encoder.
static bool heldAtLimit(int32_t delta, int32_t otherDelta, uint8_t appliedPwm, uint8_t appliedDir,
                        float setpoint, uint16_t current, float otherSetpoint, float other) {
  float drawn = appliedDir == HIGH ? senseAmps(current) : -senseAmps(current);
  return delta >= -WC_STALL_CREEP_COUNTS && delta <= WC_STALL_CREEP_COUNTS &&
         ((otherDelta >= -WC_STALL_CREEP_COUNTS && otherDelta <= WC_STALL_CREEP_COUNTS) ||
          spinsAbout(setpoint, otherSetpoint, other)) &&
         appliedPwm >= WC_FAULT_STALL_PWM_STANDING && setpoint != 0.0f &&
         (appliedDir == HIGH) == (setpoint > 0.0f) && drawn >= WC_STALL_CURRENT;
}

// Standing by its current: the wheel driven toward its setpoint, its motor drawing
// WC_STANDING_DRAW_SHARE or more of what its duty drives through a standing armature
// (WC_MOTOR_AMPS_PER_DUTY a duty), the way it is driven: its back-EMF, so its speed, a
// quarter of its duty's or less; and its partner short of its own setpoint (slower than
// WC_FAULT_EFFORT_SHORTFALL of it): the chair is loaded, not this wheel alone. Below full
// torque it stalls after WC_FAULT_STALL_TICKS_LOADED count-less ticks (checkWheel): a wheel
// standing under a load creeps; a cut encoder's wheel that turns draws less.
static bool standsByCurrent(uint8_t appliedPwm, uint8_t appliedDir, float setpoint, uint16_t current,
                            float otherSetpoint, float other) {
  if (setpoint == 0.0f || (appliedDir == HIGH) != (setpoint > 0.0f)) return false;
  float otherProgress = otherSetpoint > 0.0f ? other : -other;
  if (otherProgress >= WC_FAULT_EFFORT_SHORTFALL * fabs(otherSetpoint)) return false;
  float drawn = appliedDir == HIGH ? senseAmps(current) : -senseAmps(current);
  return drawn >= WC_MOTOR_DRAW_MIN && drawn >= WC_STANDING_DRAW_SHARE * ((float)appliedPwm * WC_MOTOR_AMPS_PER_DUTY);
}

// The wheel turning its setpoint's way (WC_FAULT_STANDING_SPEED or more, and counting this
// tick: not a wheel just locked whose filtered speed lags), its motor draws
// WC_MOTOR_DRAW_MIN or more the way its effort calls for, and WC_MOTOR_DRAW_SHARE or more
// of the current that effort (effortOf's: within the driver's current limit) drives
// through the armature: it works, and its effort without progress is its wheel's load,
// not a dead motor (which draws nothing). A reversed encoder's wheel turning toward its
// setpoint reads a speed against it (one rolled back against it reads progress: the
// reversal and runaway rules'). Not inlined, and effortOf's clamp written out: either
// way round it moved a switch's jump table into .data, and with it Timer0's start.
static __attribute__((noinline)) bool motorDraws(uint8_t appliedPwm, uint8_t appliedDir, float setpoint, float measured,
                                                int32_t delta, uint16_t current) {
  if (setpoint == 0.0f || delta == 0) return false;
  bool forward = setpoint > 0.0f;
  float progress = forward ? measured : -measured;
  if (progress < WC_FAULT_STANDING_SPEED) return false;
  // effortOf's effort, within the driver's current limit
  float effort = ((appliedDir == HIGH) == forward ? (float)appliedPwm : -(float)appliedPwm) -
                 WC_FAULT_EFFORT_EMF * progress;
  if (effort <= -WC_FAULT_EFFORT_MAX) effort = -WC_FAULT_EFFORT_MAX;
  else if (effort >= WC_FAULT_EFFORT_MAX) effort = WC_FAULT_EFFORT_MAX;
  float called = effort * WC_MOTOR_AMPS_PER_DUTY * WC_MOTOR_DRAW_SHARE;
  float drawn = forward ? senseAmps(current) : -senseAmps(current);
  if (called > 0.0f) return drawn >= WC_MOTOR_DRAW_MIN && drawn >= called;
  if (called < 0.0f) return drawn <= -WC_MOTOR_DRAW_MIN && drawn <= called;
  return false;
}

// The motor draws less than WC_MOTOR_DRAW_MIN either way while its duty and its wheel's
// speed call for WC_MOTOR_SILENT_CURRENT or more, either way (the duty, forward positive,
// less WC_FAULT_EFFORT_EMF a rad/s of the measured speed, over the armature): an open
// winding or a dead driver, its wheel carried by the chair.
static bool motorSilent(uint8_t appliedPwm, uint8_t appliedDir, float measured, uint16_t current) {
  float duty = appliedDir == HIGH ? (float)appliedPwm : -(float)appliedPwm;
  float called = (duty - WC_FAULT_EFFORT_EMF * measured) * WC_MOTOR_AMPS_PER_DUTY;
  return fabs(called) >= WC_MOTOR_SILENT_CURRENT && fabs(senseAmps(current)) < WC_MOTOR_DRAW_MIN;
}

// The PID's bounds (pidBounds) within WC_STALL_HELD_OUTPUT either way, for a wheel held
// at its current limit.
static void heldBounds(float& lo, float& hi) {
  if (hi > WC_STALL_HELD_OUTPUT) hi = WC_STALL_HELD_OUTPUT;
  if (lo < -WC_STALL_HELD_OUTPUT) lo = -WC_STALL_HELD_OUTPUT;
}

static uint8_t checkWheel(int32_t delta, uint32_t illegal, uint8_t storm, uint8_t appliedPwm,
                          uint8_t appliedDir, float setpoint, float measured, float other,
                          uint8_t otherPwm, bool otherOverruns, uint8_t& stallTicks,
                          uint8_t& reverseTicks, uint8_t& runawayTicks, uint8_t& effortPwm,
                          float& effortSpeed, float& effortSetpoint, uint8_t& effortTicks,
                          float prevMeasured, bool held, bool loaded) {
  if (storm || illegal >= WC_FAULT_ILLEGAL_PER_TICK) return WHEEL_IMPLAUSIBLE;
  // A wheel that stands while its partner does not carry the chair its way (stands, or
  // rolls back) may stand on a grade below the motor's full torque.
  float otherAlong = setpoint > 0.0f ? other : -other;
  bool standing = fabs(prevMeasured) < WC_FAULT_STANDING_SPEED && otherAlong < WC_FAULT_STANDING_SPEED;
  uint8_t stallPwm = standing ? WC_FAULT_STALL_PWM_STANDING : WC_FAULT_STALL_PWM;
  bool driven = appliedPwm >= stallPwm && setpoint != 0.0f &&
                (appliedDir == HIGH) == (setpoint > 0.0f);
  // held at its current limit (heldAtLimit): the stall timeout's, not a stalled encoder
  bool stalled = driven && delta == 0 && !held;
  stallTicks = stalled ? stallTicks + 1 : 0;
  bool turning = prevMeasured != 0.0f && (prevMeasured > 0.0f) != (setpoint > 0.0f);
  // Standing by its current on a loaded chair (standsByCurrent) below full torque, it may
  // stand a while: a wheel at the edge of moving creeps a count every tick or two.
  uint8_t stallLimit = loaded && appliedPwm < WC_FAULT_STALL_PWM_STANDING ? WC_FAULT_STALL_TICKS_LOADED
                       : turning ? WC_FAULT_STALL_TICKS_TURNING : WC_FAULT_STALL_TICKS;
  if (stallTicks >= stallLimit) return WHEEL_STALLED;
  float approach = setpoint > 0.0f ? measured - prevMeasured : prevMeasured - measured;
  // a wheel driven the way it reads (its PID still drives it the way it went) agrees with
  // its encoder: a reversed encoder reads against the way its wheel is driven
  bool drivesItsWay = appliedPwm > 0 && (appliedDir == HIGH) == (measured > 0.0f);
  bool against = fabs(setpoint) >= WC_FAULT_REVERSE_SPEED && fabs(measured) >= WC_FAULT_REVERSE_SPEED &&
                 (setpoint > 0.0f) != (measured > 0.0f) && approach < WC_FAULT_REVERSE_APPROACH &&
                 !drivesItsWay;
  reverseTicks = against ? reverseTicks + 1 : 0;
  if (reverseTicks >= WC_FAULT_REVERSE_TICKS) return WHEEL_REVERSED;
  // driving, a leaky count: one tick short of the gain (the speed-up wavers) does not start
  // it over; holding, it does (the hold's wheels rolled back by a grade beyond it)
  if (runsAway(appliedPwm, appliedDir, setpoint, measured, prevMeasured)) runawayTicks++;
  else runawayTicks = (runawayTicks > 0 && !holding) ? runawayTicks - 1 : 0;
  if (runawayTicks >= WC_FAULT_RUNAWAY_TICKS) return WHEEL_REVERSED;
  bool noProgress = noEffect(appliedPwm, appliedDir, setpoint, measured, other, otherPwm, otherOverruns,
                             effortPwm, effortSpeed, effortSetpoint, effortTicks);
  // held at its current limit, its motor draws it: no dead motor, no effort to count
  if (held) effortTicks = 0;
  else if (noProgress) return WHEEL_NO_EFFECT;
  return (stalled || against) ? WHEEL_SUSPECT : WHEEL_OK;
}

// A stalled wheel that stood (slower than WC_FAULT_STANDING_SPEED when the PID last ran)
// while the other wheel rolls WC_FAULT_STANDING_SPEED or more against this wheel's
// setpoint: the chair pivots back about the standing wheel, which its full torque
// (WC_FAULT_STALL_PWM_STANDING) cannot move, the chair's limit (a turn on a grade). A cut
// encoder's wheel turns its way and carries the chair with it.
static bool stallsLoaded(float setpoint, float prevMeasured, float other) {
  float along = setpoint > 0.0f ? other : -other;
  return fabs(prevMeasured) < WC_FAULT_STANDING_SPEED && along <= -WC_FAULT_STANDING_SPEED;
}

// A wheel at the chair's limit rather than faulty. No effect (check) with an effort that
// does not lead the other wheel's (leads: effortLeads), slower than WC_GRADE_STALL of its
// setpoint its way (stalls), while the other wheel strains toward its setpoint
// (otherStrains: straining) or shows effort without progress too (otherEffort): both
// wheels held back to a crawl is a grade beyond the chair, not a motor. A reversal
// (check) while the other wheel strains, or its reversed, runaway or effort count runs:
// both wheels pushed back. One wheel alone is a fault; both at once are the world (a
// grade, a command beyond the chair).
static bool atLimit(uint8_t check, bool leads, bool stalls, bool otherStrains, uint8_t otherReverse,
                    uint8_t otherRunaway, uint8_t otherEffort) {
  if (check == WHEEL_NO_EFFECT) return !leads && stalls && (otherStrains || otherEffort != 0);
  return check == WHEEL_REVERSED &&
         (otherStrains || otherReverse != 0 || otherRunaway != 0 || otherEffort != 0);
}

// Stalling: slower than WC_GRADE_STALL of its setpoint its way (or against it).
static bool stalling(float setpoint, float measured) {
  float progress = setpoint > 0.0f ? measured : -measured;
  return progress < WC_GRADE_STALL * fabs(setpoint);
}

// The fault bits of one wheel's check (its stall, reversed, implausible and motor bits).
static uint16_t wheelFaults(uint8_t check, uint16_t stall, uint16_t reversed, uint16_t implausible,
                            uint16_t motor) {
  if (check == WHEEL_STALLED) return stall;
  if (check == WHEEL_REVERSED) return reversed;
  if (check == WHEEL_IMPLAUSIBLE) return implausible;
  if (check == WHEEL_NO_EFFECT) return motor;
  return 0;
}

// A wheel driven on the way it went when the emergency ramp began takes back the
// integral it held then (held, at setpoint was), in the share its setpoint kept of was;
// otherwise 0. Without it the PID rebuilds from zero while the chair still rolls: the
// duty collapses, the wheel brakes on its own back-EMF (from 1 m/s to under half of it
// after a 0.5 s silence), and the motor rule takes the duty climbing back for a dead
// motor.
static float resumedIntegral(float held, float was, float setpoint, float target) {
  if (was == 0.0f || setpoint == 0.0f || (setpoint > 0.0f) != (was > 0.0f) ||
      (target > 0.0f) != (was > 0.0f)) {
    return 0.0f;
  }
  float share = setpoint / was;
  return share >= 1.0f ? held : held * share;
}

// A valid command: new wheel targets, through the pivot state machine. One that drives
// on during an emergency ramp takes the integrals back (resumedIntegral).
static void acceptCommand(uint8_t newMode, float right, float left) {
  mode = newMode;
  cmdSinceTick = true;
  bool resuming = emergencyStop;
  emergencyStop = false;
  float travel = (right + left) * 0.5f * WC_WHEEL_RADIUS;
  if (right == 0.0f && left == 0.0f) {
    pivotPhase = PIVOT_NONE;       // a stop is honoured at once, even mid-pivot
    pivotTicksLeft = 0;
    targetR = targetL = 0.0f;
  } else if (needsPivot(travel, lastTravel)) {
    pivotPhase = PIVOT_STOPPING;   // first come to rest, then rotate
    pivotTicksLeft = 0;
    pendingR = right;
    pendingL = left;
    targetR = targetL = 0.0f;
  } else if (pivotPhase != PIVOT_NONE) {
    pendingR = right;
    pendingL = left;
  } else {
    targetR = right;
    targetL = left;
    if (resuming) {
      integralL = resumedIntegral(haltIntegralL, haltSetpointL, setpointL, left);
      integralR = resumedIntegral(haltIntegralR, haltSetpointR, setpointR, right);
    }
  }
  lastTravel = travel;
}

// printWheel: <label><p|n><|v|>, the magnitude with 2 decimals as VEL prints it: the
// tail of a feedback line in feedback_form 1 (a sign of its own would read as "-?").
static void printWheel(const __FlashStringHelper* label, float v) {
  line.print(label);
  line.write(v < 0.0f ? 'n' : 'p');
  line.print(fabs(v), 2);
}

// TLM:<millis>,<rx bytes>,<seq>,<pwmL>,<pwmR>,<dirL>,<dirR>,<illegalL>,<illegalR>,
//     <flags>,<rejected>,<crc rejected>,<free RAM>,<faults>,<rx lost>,<late>,<state>,
//     <supply dV>   (protocol/PROTOCOL.md)
static void sendTelemetry(uint32_t now) {
  uint8_t flags = (watchdogArmed ? 1 : 0) | (emergencyStop ? 2 : 0) | (estopLatched ? 4 : 0) |
                  (ppmLost ? 8 : 0) | (parked ? 16 : 0) | (uint8_t)(pivotPhase << 5) |
                  (faultFlags != 0 ? 128 : 0);
  // state: bit 0 waiting for neutral (motion refused), 1 the neutral fault, 2 driving
  // inhibited, 3 the speed capped by an inhibit input, 4 a fitted brake applied, 5 push
  // mode (the brake released by hand), 6 the thermal rollback, 7 the low-battery rollback,
  // 8 and 9 the drive profile in force
  uint8_t engaged = inhibitEngaged();
  uint16_t state = ((uint16_t)profile << 8) | (needNeutral ? 1 : 0) | (neutralFault ? 2 : 0) | ((engaged & INHIBIT_STOP_MASK) ? 4 : 0) |
                  ((engaged & (uint8_t)~INHIBIT_STOP_MASK) ? 8 : 0) | (brakeFitted && !brakeReleased ? 16 : 0) |
                  ((engaged & INHIBIT_PUSH) ? 32 : 0) | (thermalRollback ? 64 : 0) | (batteryLow ? 128 : 0);
  const uint32_t fields[] = {
    now, rxCount, lastSeq, pwmL, pwmR, dirL, dirR, illTickL, illTickR, flags, rejectedCount,
    crcRejected, freeRam, faultFlags, rxLostTick, lateTicks, state,
    (uint32_t)(supplyVolts * 10.0f + 0.5f),   // the filtered supply, tenths of a volt
  };
  line.print(F("TLM:"));
  for (uint8_t i = 0; i < sizeof(fields) / sizeof(fields[0]); i++) {
    if (i) line.write(',');
    line.printU32(fields[i]);
  }
  line.println();
  line.send();
}

extern "C" __attribute__((noinline)) void controlTick(uint32_t now) {
  uint32_t elapsed = now - lastTickTime;   // since the last tick ran: what the counts span
  float dt = (float)elapsed / 1000.0f;
  lastTickTime = now;
  // Ticks on a fixed grid: the next one is due a period after this one was due, so a
  // late tick does not delay the ones after it. More than a period late (loop() held
  // up): this tick runs and the grid starts again from now, counted in lateTicks.
  if (now - lastControlTime >= 2 * WC_CONTROL_PERIOD_MS) {
    lastControlTime = now;
    lateTicks++;
  } else {
    lastControlTime += WC_CONTROL_PERIOD_MS;
  }
  // The output budget refills by what the UART surely sent meanwhile.
  if (elapsed >= WC_TX_CREDIT_MAX / WC_TX_CREDIT_PER_MS) {
    txCredit = WC_TX_CREDIT_MAX;
  } else {
    txCredit = (uint16_t)min((uint32_t)WC_TX_CREDIT_MAX, txCredit + elapsed * WC_TX_CREDIT_PER_MS);
  }
  tickCount++;

  // What the interrupts wrote, copied with them off (loads only: an encoder interrupt
  // must not wait more than a few dozen cycles), summed after.
  int32_t countL, countR;
  int8_t stepsL, stepsR;
  uint32_t illL, illR;
  uint8_t illStepsL, illStepsR;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    countL = encoderValueL;
    stepsL = encAccL;
    countR = encoderValueR;
    stepsR = encAccR;
    illL = illegalL;
    illStepsL = illAccL;
    illR = illegalR;
    illStepsR = illAccR;
    stormTickL = stormL != 0;   // the ISR sets a non-zero byte
    stormTickR = stormR != 0;
    rxLostTick = rxLost;
  }
  inhibitTick = (digitalRead(WC_PIN_INHIBIT_1) == LOW ? 1 : 0) | (digitalRead(WC_PIN_INHIBIT_2) == LOW ? 2 : 0) |
                (digitalRead(WC_PIN_PUSH) == LOW ? INHIBIT_PUSH : 0);
  brakeStatusTick = digitalRead(WC_PIN_BRAKE_STATUS) == LOW ? 1 : 0;
  // The ADC interrupt's chain the last tick started (the currents, 0.2 ms on, then the
  // supply's conversion, 0.3 ms on: long done), then the next one (ISR(ADC_vect)). A tick
  // that came before it was done (none does: a tick takes longer) would keep the last
  // counts and let it finish.
  if (!(ADCSRA & (_BV(ADSC) | _BV(ADIE)))) {
    supplyTick = ADC;
    currentTickL = adcCurrentL;
    currentTickR = adcCurrentR;
    ADMUX = _BV(REFS0) | (WC_PIN_CURRENT_L & 7);
    // ADIF written 1 (the supply's conversion set it, its interrupt off) clears it in the
    // write that sets ADIE: else the interrupt would come at once
    ADCSRA = _BV(ADEN) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0) | _BV(ADIF) | _BV(ADIE) | _BV(ADSC);
  }
  encTickL = countL + stepsL;
  encTickR = countR + stepsR;
  uint32_t illNowL = illL + illStepsL;
  uint32_t illNowR = illR + illStepsR;
  uint32_t illDeltaL = illNowL - illTickL;
  uint32_t illDeltaR = illNowR - illTickR;
  illTickL = illNowL;
  illTickR = illNowR;
  int32_t deltaL = (int32_t)((uint32_t)encTickL - (uint32_t)prevEncL);
  int32_t deltaR = (int32_t)((uint32_t)encTickR - (uint32_t)prevEncR);
  prevEncL = encTickL;
  prevEncR = encTickR;

  // The left wheel is mounted mirrored: its counts run backwards.
  rawVelL = -((float)deltaL / WC_CPR) * (WC_TWO_PI / dt);
  rawVelR = ((float)deltaR / WC_CPR) * (WC_TWO_PI / dt);
  filtVelL = WC_ALPHA * rawVelL + (1.0f - WC_ALPHA) * filtVelL;
  filtVelR = WC_ALPHA * rawVelR + (1.0f - WC_ALPHA) * filtVelR;

  updateThermal(dt);
  updateSupply();
  // Faults: checked until one latches. A new one stops the chair (motors off below).
  // The chair's limits are not faults: they park it (halt) under the hold, braking hardest
  // (hardest) on an overspeed.
  uint8_t checkL = WHEEL_OK, checkR = WHEEL_OK;
  bool stallHeldL = false, stallHeldR = false;
  bool halt = false, hardest = false;
  if (faultFlags == 0) {
    bool strainL = straining(pwmL, dirL, setpointL, filtVelL);
    bool strainR = straining(pwmR, dirR, setpointR, filtVelR);
    bool overrunL = overruns(pwmL, dirL, setpointL, filtVelL);
    bool overrunR = overruns(pwmR, dirR, setpointR, filtVelR);
    stallHeldL = heldAtLimit(deltaL, deltaR, pwmL, dirL, setpointL, currentTickL, setpointR, filtVelR);
    stallHeldR = heldAtLimit(deltaR, deltaL, pwmR, dirR, setpointR, currentTickR, setpointL, filtVelL);
    bool loadedL = standsByCurrent(pwmL, dirL, setpointL, currentTickL, setpointR, filtVelR);
    bool loadedR = standsByCurrent(pwmR, dirR, setpointR, currentTickR, setpointL, filtVelL);
    checkL = checkWheel(deltaL, illDeltaL, stormTickL, pwmL, dirL, setpointL, filtVelL, filtVelR,
                        pwmR, overrunR, stallTicksL, reverseTicksL, runawayTicksL, effortPwmL, effortSpeedL,
                        effortSetpointL, effortTicksL, prevMeasL, stallHeldL, loadedL);
    checkR = checkWheel(deltaR, illDeltaR, stormTickR, pwmR, dirR, setpointR, filtVelR, filtVelL,
                        pwmL, overrunL, stallTicksR, reverseTicksR, runawayTicksR, effortPwmR, effortSpeedR,
                        effortSetpointR, effortTicksR, prevMeasR, stallHeldR, loadedR);
    // Driving, a wheel held at its current limit runs the stall timeout's clock.
    stallTime = (!holding && (stallHeldL || stallHeldR)) ? stallTime + dt : 0.0f;
    // Effort without progress is one motor's only while its effort leads the other's and
    // the motor does not draw what its effort calls for, turning or standing loaded (a
    // working motor's is its load). A partner that draws nothing of what its own duty and
    // speed call for is then the dead one.
    bool drawsL = loadedL || motorDraws(pwmL, dirL, setpointL, filtVelL, deltaL, currentTickL);
    bool drawsR = loadedR || motorDraws(pwmR, dirR, setpointR, filtVelR, deltaR, currentTickR);
    bool leadL = checkL == WHEEL_NO_EFFECT &&
                 effortLeads(pwmL, dirL, setpointL, filtVelL, pwmR, dirR, setpointR, filtVelR);
    bool leadR = checkR == WHEEL_NO_EFFECT &&
                 effortLeads(pwmR, dirR, setpointR, filtVelR, pwmL, dirL, setpointL, filtVelL);
    bool leadsL = leadL && !drawsL, leadsR = leadR && !drawsR;
    if (leadL && drawsL && (checkR == WHEEL_OK || checkR == WHEEL_SUSPECT || checkR == WHEEL_NO_EFFECT) &&
        motorSilent(pwmR, dirR, filtVelR, currentTickR)) {
      checkR = WHEEL_NO_EFFECT;
      leadsR = true;
    }
    if (leadR && drawsR && (checkL == WHEEL_OK || checkL == WHEEL_SUSPECT || checkL == WHEEL_NO_EFFECT) &&
        motorSilent(pwmL, dirL, filtVelL, currentTickL)) {
      checkL = WHEEL_NO_EFFECT;
      leadsL = true;
    }
    // Driving only: a held wheel that runs away is a fault (a reversed encoder turns the
    // hold into positive feedback), whatever the other wheel does.
    bool limitL = !holding && atLimit(checkL, leadsL, stalling(setpointL, filtVelL), strainR,
                                      reverseTicksR, runawayTicksR, effortTicksR);
    bool limitR = !holding && atLimit(checkR, leadsR, stalling(setpointR, filtVelR), strainL,
                                      reverseTicksL, runawayTicksL, effortTicksL);
    // A wheel that stood at full torque while its partner rolled back against its way:
    // the chair pivots back about it, beyond what the motors hold (a turn on a grade).
    if (!holding && checkL == WHEEL_STALLED && checkR != WHEEL_STALLED)
      limitL = limitL || stallsLoaded(setpointL, prevMeasL, filtVelR);
    if (!holding && checkR == WHEEL_STALLED && checkL != WHEEL_STALLED)
      limitR = limitR || stallsLoaded(setpointR, prevMeasR, filtVelL);
    // The limit, or a load both wheels share short of it (no lead): not a fault.
    if (limitL || (checkL == WHEEL_NO_EFFECT && !leadsL)) checkL = WHEEL_OK;
    if (limitR || (checkR == WHEEL_NO_EFFECT && !leadsR)) checkR = WHEEL_OK;
    bool overL = overspeedRun(!holding && overspeeding(pwmL, dirL, setpointL, targetL, filtVelL),
                              filtVelL, prevMeasL, overspeedTicksL, overspeedFromL);
    bool overR = overspeedRun(!holding && overspeeding(pwmR, dirR, setpointR, targetR, filtVelR),
                              filtVelR, prevMeasR, overspeedTicksR, overspeedFromR);
    // One wheel gaining speed beyond its setpoint however hard it is braked, for
    // WC_OVERSPEED_ONE_TICKS ticks, while the other brakes at the current limit too (its
    // effort WC_FAULT_EFFORT_MAX against its setpoint: the chair is going down a grade)
    // and holds (not overspeeding at all): its motor does not brake. Gravity beating both
    // brakes is the chair's (OVERSPEED, below); a wheel pushed on while its partner
    // drives is the runaway rule's.
    if (overL && overspeedTicksL >= WC_OVERSPEED_ONE_TICKS && overspeedTicksR == 0 &&
        effortOf(pwmR, dirR, setpointR, filtVelR) <= -WC_FAULT_EFFORT_MAX &&
        (checkL == WHEEL_OK || checkL == WHEEL_SUSPECT)) {
      checkL = WHEEL_NO_EFFECT;
    }
    if (overR && overspeedTicksR >= WC_OVERSPEED_ONE_TICKS && overspeedTicksL == 0 &&
        effortOf(pwmL, dirL, setpointL, filtVelL) <= -WC_FAULT_EFFORT_MAX &&
        (checkR == WHEEL_OK || checkR == WHEEL_SUSPECT)) {
      checkR = WHEEL_NO_EFFECT;
    }
    uint16_t faults;
    if (checkL == WHEEL_STALLED && checkR == WHEEL_STALLED) {
      faults = FAULT_DRIVER;   // both wheels driven, neither turns: the driver or its supply
    } else {
      faults = wheelFaults(checkL, FAULT_STALL_L, FAULT_REVERSED_L, FAULT_IMPLAUSIBLE_L, FAULT_MOTOR_L) |
               wheelFaults(checkR, FAULT_STALL_R, FAULT_REVERSED_R, FAULT_IMPLAUSIBLE_R, FAULT_MOTOR_R);
    }
    if (faults == 0) faults = brakeCoilFault();
    if (faults == 0) faults = thermalFault();
    if (faults == 0) faults = batteryFault();
    if (faults == 0) faults = currentSenseFault();
    if (faults != 0) {
      faultFlags = faults;
      stallTime = 0.0f;
      emergencyHalt();
      cmdSinceTick = false;
      watchdogArmed = false;
      stallTicksL = stallTicksR = reverseTicksL = reverseTicksR = 0;
      runawayTicksL = runawayTicksR = 0;
      sendFaultEvents(faults);
    } else if (overL && overR) {
      // both wheels: gravity on the whole chair (one alone is its motor's fault, above)
      halt = hardest = true;
      sendEvent(F("OVERSPEED"));
    } else if (limitL || limitR) {
      halt = true;
      sendEvent(F("STALLED_ON_GRADE"));
    } else if (stallTime >= stallTimeout) {
      // held at the current limit too long (a wall, a kerb): motion needs a neutral command
      halt = true;
      requireNeutral();
      sendEvent(F("STALL_TIMEOUT"));
    }
    if (halt) {
      limitLatched = true;
      emergencyHalt();
      setpointL = setpointR = 0.0f;
      stallTicksL = stallTicksR = reverseTicksL = reverseTicksR = 0;
      runawayTicksL = runawayTicksR = 0;
      effortTicksL = effortTicksR = 0;
      overspeedTicksL = overspeedTicksR = 0;
      stallTime = 0.0f;
    }
  }

  updateInhibits();
  if (cmdSinceTick) {
    cmdSinceTick = false;
    lastCmdTime = now;
    watchdogArmed = true;
  }
  if (watchdogArmed && now - lastCmdTime >= watchdogMs) {
    // A stop of motion the host asked for: when the link comes back, its first command
    // must be neutral. (After a neutral command there is no stale motion to resume.)
    bool driving = targetL != 0.0f || targetR != 0.0f || pivotPhase != PIVOT_NONE;
    watchdogArmed = false;
    emergencyHalt();
    if (driving) requireNeutral();
    sendEvent(F("WATCHDOG"));
  } else if (inhibitPending) {
    // one inhibit event a tick, in the slot of the wait for neutral's (which waits a tick)
    uint8_t bit = inhibitPending & (uint8_t)-inhibitPending;   // the lowest
    inhibitPending &= (uint8_t)~bit;
    if (bit == 1) sendEvent(F("INHIBIT,1,1"));
    else if (bit == 2) sendEvent(F("INHIBIT,1,0"));
    else if (bit == 4) sendEvent(F("INHIBIT,2,1"));
    else if (bit == 8) sendEvent(F("INHIBIT,2,0"));
    else if (bit == 16) sendEvent(F("PUSH,1"));
    else sendEvent(F("PUSH,0"));
  } else if (thermalPending) {
    // ...and so is the thermal rollback's, on first
    if (thermalPending & 1) {
      thermalPending &= 2;
      sendEvent(F("THERMAL,1"));
    } else {
      thermalPending = 0;
      sendEvent(F("THERMAL,0"));
    }
  } else if (batteryPending) {
    // ...and the low-battery rollback's
    if (batteryPending & 1) {
      batteryPending &= 2;
      sendEvent(F("BATTERY,1"));
    } else {
      batteryPending = 0;
      sendEvent(F("BATTERY,0"));
    }
  } else if (needNeutral) {
    // The wait for neutral, at most one event a tick (none beside WATCHDOG: the output
    // budget's worst tick): the refusal (EVT:NOT_NEUTRAL); the neutral command stood
    // WC_NEUTRAL_TICKS ticks, confirmed (EVT:NEUTRAL when something was refused
    // meanwhile); refused WC_NEUTRAL_FAULT_TICKS ticks without a neutral command, a
    // deflected control (EVT:DEFLECTED, until neutral).
    if (notNeutralPending) {
      notNeutralPending = false;
      sendEvent(F("NOT_NEUTRAL"));
    } else if (neutralSeen) {
      if (++neutralTicks >= WC_NEUTRAL_TICKS) {
        if (notNeutralSent) sendEvent(F("NEUTRAL"));
        needNeutral = false;
        neutralSeen = false;
        notNeutralSent = false;
        neutralFault = false;
      }
    } else if (notNeutralSent && !neutralFault && ++notNeutralTicks >= WC_NEUTRAL_FAULT_TICKS) {
      neutralFault = true;
      sendEvent(F("DEFLECTED"));
    }
  }

  float goalL, goalR;
  dampedTargets(goalL, goalR);
  driveCaps(goalL, goalR);
  float share = inhibitShare();
  float hotShare = thermalShare();
  if (hotShare < share) share = hotShare;
  float lowShare = batteryShare();
  if (lowShare < share) share = lowShare;
  if (share < 1.0f) {   // an inhibit's or a rollback's cap: the faster wheel at its share, the curvature kept
    float cap = maxWheel * share;
    float peak = fabs(goalL) > fabs(goalR) ? fabs(goalL) : fabs(goalR);
    if (peak > cap) {
      float k = cap / peak;
      goalL *= k;
      goalR *= k;
    }
  }
  if (brakeFitted && brakePhase != BRAKE_RELEASED) {
    goalL = goalR = 0.0f;   // the brake not yet let go: the setpoints wait at zero
  }
  rampSetpoints(goalL, goalR, dt);
  if (brakeFitted && faultFlags != 0) {
    // the brake applied at the fault stops the wheels faster than the emergency ramp: the
    // PID may brake them with it, never drive them against it
    setpointL = brakingSetpoint(setpointL, filtVelL);
    setpointR = brakingSetpoint(setpointR, filtVelR);
  }
  // Stopped (target and setpoint zero, no pivot under way), an integral that drives a
  // wheel the way it still turns is dropped: it held the chair up a grade and would carry
  // it on past the stop.
  if (pivotPhase == PIVOT_NONE) {
    if (targetL == 0.0f && setpointL == 0.0f && integralL != 0.0f &&
        (integralL > 0.0f) == (filtVelL > 0.0f)) {
      integralL = 0.0f;
    }
    if (targetR == 0.0f && setpointR == 0.0f && integralR != 0.0f &&
        (integralR > 0.0f) == (filtVelR > 0.0f)) {
      integralR = 0.0f;
    }
  }

  bool still = fabs(filtVelL) < WC_STILL_SPEED && fabs(filtVelR) < WC_STILL_SPEED;
  if (!still) {
    stillTicks = 0;
  } else if (stillTicks < 255) {
    stillTicks++;
  }
  bool atRest = targetL == 0.0f && targetR == 0.0f && setpointL == 0.0f && setpointR == 0.0f;
  // A wheel's encoder is trusted until a fault of its own, or the driver's, latches.
  bool trustedL = (faultFlags & FAULTS_UNTRUSTED_L) == 0;
  bool trustedR = (faultFlags & FAULTS_UNTRUSTED_R) == 0;
  // Park: at rest and both trusted wheels slower than WC_BRAKE_DONE_SPEED. An emergency
  // ramp (watchdog, PPM loss, e-stop, a fault) keeps braking under closed loop until
  // then, and parks at once. Parked, the hold (below) keeps the chair where it stops.
  // A fault that leaves no encoder trusted (both wheels', or the driver's) parks at once
  // at duty 0: no closed loop is left, the driver brakes the motors.
  bool braked = (!trustedL || fabs(filtVelL) < WC_BRAKE_DONE_SPEED) &&
                (!trustedR || fabs(filtVelR) < WC_BRAKE_DONE_SPEED);
  // Once the hold is on, the chair stays parked while at rest, moving or not: the hold
  // (below) keeps it where it stopped. With a brake, the chair stays parked until the
  // brake has let go (brakeStep).
  // In push mode the chair stays parked at rest however fast it is pushed (the PID would
  // brake it; the motors freewheel instead).
  bool pushing = (inhibitStable & INHIBIT_PUSH) != 0;
  bool park = (!trustedL && !trustedR) || halt || (atRest && (holding || braked || pushing));
  if (brakeFitted) park = brakeStep(park);
  if (park) {
    parked = true;
    integralL = integralR = 0.0f;
    prevMeasL = filtVelL;
    prevMeasR = filtVelR;
    outputL = outputR = 0.0f;
  } else {
    parked = false;
    // A suspect wheel keeps its output: no count is no reason to push harder.
    // Past the thermal rollback's start, each within its motor's rolled-back current limit.
    float lo, hi;
    // A wheel held at its current limit pushes at the motor's full torque, no harder
    // (heldBounds: its current then bounds how fast it can turn).
    if (trustedL && checkL != WHEEL_SUSPECT) {
      pidBounds(windingTempL, filtVelL, lo, hi);
      if (stallHeldL) heldBounds(lo, hi);
      outputL = computePID(setpointL, filtVelL, integralL, prevMeasL, kpL, kiL, kdL, dt, lo, hi);
    }
    if (trustedR && checkR != WHEEL_SUSPECT) {
      pidBounds(windingTempR, filtVelR, lo, hi);
      if (stallHeldR) heldBounds(lo, hi);
      outputR = computePID(setpointR, filtVelR, integralR, prevMeasR, kpR, kiR, kdR, dt, lo, hi);
    }
    // After a fault, the faulty wheel at duty 0: the driver brakes it whichever way it
    // turns (the healthy one's output would drive it on in a turn).
    if (!trustedL) outputL = 0.0f;
    if (!trustedR) outputR = 0.0f;
    if (brakeFitted && faultFlags != 0) {   // with the brake applied: braking only
      outputL = brakingOutput(outputL, rawVelL);
      outputR = brakingOutput(outputR, rawVelR);
    }
  }
  // Parked, the hold drives each wheel whose encoder is trusted, and a faulty wheel
  // mirrors the healthy one's hold, open loop.
  bool heldL = parked && trustedL && !pushing;
  bool heldR = parked && trustedR && !pushing;
  if (parked && pushing) {
    pushMotor(WC_PIN_PWM_L, WC_PIN_DIR_L, trustedL, filtVelL, pwmL, dirL);
    pushMotor(WC_PIN_PWM_R, WC_PIN_DIR_R, trustedR, filtVelR, pwmR, dirR);
    holding = false;
  } else if (heldL || heldR) {
    if (!holding) {   // the hold starts: from this tick's counts, following a wheel still moving
      holdRefL = encTickL;
      holdRefR = encTickR;
      holdStepL = deltaL;
      holdStepR = deltaR;
      holdRollaway = false;
    }
    if (hardest) holdRollaway = true;
    int32_t errL = heldL ? holdError(encTickL, deltaL, holdRefL, holdStepL) : 0;
    int32_t errR = heldR ? holdError(encTickR, deltaR, holdRefR, holdStepR) : 0;
    bool rolled = errL > WC_ROLLAWAY_COUNTS || errL < -WC_ROLLAWAY_COUNTS ||
                  errR > WC_ROLLAWAY_COUNTS || errR < -WC_ROLLAWAY_COUNTS;
    if (rolled && !holdRollaway) {
      holdRollaway = true;
      sendEvent(F("ROLLAWAY"));
    }
    // A wheel whose encoder is not trusted mirrors the healthy wheel's hold, open loop
    // (the same duty against the same motion): on a grade both carry half the chair.
    // While the brake holds, the motors are unpowered; they hold again after a rollaway
    // (the brake slips) or a coil fault (it may not hold).
    if (brakeFitted && brakePhase == BRAKE_ENGAGED && !holdRollaway && (faultFlags & FAULTS_BRAKE) == 0) {
      errL = errR = 0;
    }
    holdMotor(WC_PIN_PWM_L, WC_PIN_DIR_L, heldL ? errL : -errR, HIGH, pwmL, dirL);
    holdMotor(WC_PIN_PWM_R, WC_PIN_DIR_R, heldR ? errR : -errL, LOW, pwmR, dirR);
    holding = true;
  } else {
    setMotor(WC_PIN_PWM_L, WC_PIN_DIR_L, outputL, pwmL, dirL);
    setMotor(WC_PIN_PWM_R, WC_PIN_DIR_R, outputR, pwmR, dirR);
    holding = false;
  }
  // Without a brake fitted, the pin is LOW whenever the PID does not drive the motors,
  // and from a fault on (brakeStep sets it with one).
  if (!brakeFitted) brakeReleased = !parked && faultFlags == 0;
  digitalWrite(WC_PIN_BRAKE, brakeReleased ? HIGH : LOW);

  bool slow = fabs(filtVelL) < WC_PIVOT_START_SPEED && fabs(filtVelR) < WC_PIVOT_START_SPEED;
  if (pivotPhase == PIVOT_STOPPING && setpointL == 0.0f && setpointR == 0.0f && slow) {
    pivotPhase = PIVOT_ROTATING;   // at rest: rotate in place so the casters swing round
    pivotTicksLeft = WC_PIVOT_TICKS;
    targetR = WC_PIVOT_SPEED;
    targetL = -WC_PIVOT_SPEED;
  } else if (pivotPhase == PIVOT_ROTATING && --pivotTicksLeft == 0) {
    pivotPhase = PIVOT_NONE;
    targetL = pendingL;
    targetR = pendingR;
  }

  line.print(F("ENC:"));
  line.printI32(encTickL);
  line.write(',');
  line.printI32(encTickR);
  line.print(F(",VEL:"));
  line.print(rawVelL, 2);
  line.print(',');
  line.print(rawVelR, 2);
  line.print(F(",MODE:"));
  line.print(mode == WC_MODE_WHEEL ? F("WHEEL") : mode == WC_MODE_CMDVEL ? F("CMDVEL") : F("PPM"));
  // feedback_form 1, for hosts that never say hello:4 (a ros2_control hardware interface
  // written for the seed-era board reads r[pn]<rad/s> and l[pn]<rad/s>): the wheels'
  // speeds again, right first as in its commands, the sign as a letter. A framed line
  // stays as it was, so a v4 host's worst tick still fits the output budget.
  if (feedbackForm && !linesFramed) {
    printWheel(F(",r"), rawVelR);
    printWheel(F(",l"), rawVelL);
  }
  line.println();
  line.send();
  if (tlmEnabled) sendTelemetry(now);

  errLinesThisTick = 0;
}

// ---------------------------------------------------------------------------
// Command framing and parsing (protocol/PROTOCOL.md)
// ---------------------------------------------------------------------------
enum ParseResult : uint8_t {
  PARSE_OK, ERR_SYNTAX, ERR_NUMBER, ERR_RANGE, ERR_FIELDS, ERR_OVERLONG, ERR_CHECKSUM, ERR_ESTOP,
  ERR_BUSY, ERR_PARAM, ERR_UNFRAMED, ERR_FAULT, ERR_OVERRUN, ERR_LIMIT, ERR_NEUTRAL, ERR_INHIBIT
};
// What a command answers besides ACK/ERR.
enum DataReply : uint8_t { DATA_NONE, DATA_HELLO, DATA_PARAM };

#define DISCARD_NONE 0
#define DISCARD_TO_COMMA 1      // an overlong seed command: up to ',' or the line end
#define DISCARD_TO_EOL 2        // an overlong framed ($) line: up to the line end
#define DISCARD_OVERRUN 3       // bytes were lost: up to ',' or the line end, then ERR:overrun

static char cmdBuf[WC_CMD_MAX_LEN + 1];
uint8_t cmdLen = 0;
uint8_t cmdCommas = 0;
uint8_t cmdDiscarding = DISCARD_NONE;
static uint8_t replyParam = 0;          // the parameter a get:/set: names

// Reason words of ERR: and NAK: lines, in ParseResult order (PARSE_OK has none).
static const char R_SYNTAX[] PROGMEM = "syntax";
static const char R_NUMBER[] PROGMEM = "number";
static const char R_RANGE[] PROGMEM = "range";
static const char R_FIELDS[] PROGMEM = "fields";
static const char R_OVERLONG[] PROGMEM = "overlong";
static const char R_CHECKSUM[] PROGMEM = "checksum";
static const char R_ESTOP[] PROGMEM = "estop";
static const char R_BUSY[] PROGMEM = "busy";
static const char R_PARAM[] PROGMEM = "param";
static const char R_UNFRAMED[] PROGMEM = "unframed";
static const char R_FAULT[] PROGMEM = "fault";
static const char R_OVERRUN[] PROGMEM = "overrun";
static const char R_LIMIT[] PROGMEM = "limit";
static const char R_NEUTRAL[] PROGMEM = "neutral";
static const char R_INHIBIT[] PROGMEM = "inhibit";
static const char* const REASONS[] = {
  R_SYNTAX, R_SYNTAX, R_NUMBER, R_RANGE, R_FIELDS, R_OVERLONG, R_CHECKSUM, R_ESTOP, R_BUSY,
  R_PARAM, R_UNFRAMED, R_FAULT, R_OVERRUN, R_LIMIT, R_NEUTRAL, R_INHIBIT,
};

// Runtime parameters: name, variable, range. The first PARAM_FLOATS are floats;
// watchdog_ms, feedback_form and brake_fitted (the last three) are integers.
#define PARAM_COUNT 22
#define PARAM_FLOATS 18
#define PARAM_DRIVE_FIRST 10   // fwd_speed: the first of a profile's PROFILE_FLOATS limits
#define PARAM_WATCHDOG 18
#define PARAM_FEEDBACK_FORM 19
#define PARAM_BRAKE_FITTED 20
#define PARAM_PROFILE 21
static const char P_KP_L[] PROGMEM = "kp_l";
static const char P_KI_L[] PROGMEM = "ki_l";
static const char P_KD_L[] PROGMEM = "kd_l";
static const char P_KP_R[] PROGMEM = "kp_r";
static const char P_KI_R[] PROGMEM = "ki_r";
static const char P_KD_R[] PROGMEM = "kd_r";
static const char P_MAX_WHEEL[] PROGMEM = "max_wheel";
static const char P_MAX_ACCEL[] PROGMEM = "max_accel";
static const char P_ESTOP_DECEL[] PROGMEM = "estop_decel";
static const char P_STALL_TIMEOUT[] PROGMEM = "stall_timeout";
static const char P_FWD_SPEED[] PROGMEM = "fwd_speed";
static const char P_REV_SPEED[] PROGMEM = "rev_speed";
static const char P_DRIVE_ACCEL[] PROGMEM = "drive_accel";
static const char P_DRIVE_DECEL[] PROGMEM = "drive_decel";
static const char P_TURN_SPEED[] PROGMEM = "turn_speed";
static const char P_TURN_ACCEL[] PROGMEM = "turn_accel";
static const char P_TURN_AT_SPEED[] PROGMEM = "turn_at_speed";
static const char P_TREMOR_DAMPING[] PROGMEM = "tremor_damping";
static const char P_WATCHDOG[] PROGMEM = "watchdog_ms";
static const char P_FEEDBACK_FORM[] PROGMEM = "feedback_form";
static const char P_BRAKE_FITTED[] PROGMEM = "brake_fitted";
static const char P_PROFILE[] PROGMEM = "profile";
static const char* const PARAM_NAMES[PARAM_COUNT] = {
  P_KP_L, P_KI_L, P_KD_L, P_KP_R, P_KI_R, P_KD_R, P_MAX_WHEEL, P_MAX_ACCEL, P_ESTOP_DECEL, P_STALL_TIMEOUT,
  P_FWD_SPEED, P_REV_SPEED, P_DRIVE_ACCEL, P_DRIVE_DECEL, P_TURN_SPEED, P_TURN_ACCEL, P_TURN_AT_SPEED,
  P_TREMOR_DAMPING, P_WATCHDOG, P_FEEDBACK_FORM, P_BRAKE_FITTED, P_PROFILE,
};
static float* const PARAM_VARS[PARAM_FLOATS] = {
  &kpL, &kiL, &kdL, &kpR, &kiR, &kdR, &maxWheel, &maxAccel, &estopDecel, &stallTimeout,
  &fwdSpeed, &revSpeed, &driveAccel, &driveDecel, &turnSpeed, &turnAccel, &turnAtSpeed, &tremorDamping,
};
static const float PARAM_MIN[PARAM_FLOATS] = {
  WC_GAIN_P_MIN, WC_GAIN_I_MIN, 0.0f, WC_GAIN_P_MIN, WC_GAIN_I_MIN, 0.0f, WC_MAX_WHEEL_MIN, WC_ACCEL_MIN,
  WC_DECEL_MIN, WC_STALL_TIMEOUT_MIN, WC_DRIVE_SPEED_MIN, WC_DRIVE_SPEED_MIN, WC_DRIVE_ACCEL_MIN, WC_DRIVE_ACCEL_MIN,
  WC_TURN_SPEED_MIN, WC_TURN_ACCEL_MIN, 0.0f, 0.0f,
};
static const float PARAM_MAX[PARAM_FLOATS] = {
  WC_GAIN_P_MAX, WC_GAIN_I_MAX, WC_GAIN_D_MAX, WC_GAIN_P_MAX, WC_GAIN_I_MAX, WC_GAIN_D_MAX,
  WC_MAX_WHEEL_SPEED, WC_ACCEL_MAX, WC_DECEL_MAX, WC_STALL_TIMEOUT_MAX, WC_DRIVE_SPEED_MAX, WC_DRIVE_SPEED_MAX, WC_DRIVE_ACCEL_MAX,
  WC_DRIVE_ACCEL_MAX, WC_TURN_SPEED_MAX, WC_TURN_ACCEL_MAX, 1.0f, WC_TREMOR_DAMPING_MAX,
};

// The drive profiles' table back to its presets.
static void presetProfiles() { memcpy_P(profileTable, PROFILE_PRESETS, sizeof(profileTable)); }

// Profile p in force: its row becomes the drive limits.
static void useProfile(uint8_t p) {
  profile = p;
  for (uint8_t i = 0; i < PROFILE_FLOATS; i++) *PARAM_VARS[PARAM_DRIVE_FIRST + i] = profileTable[p][i];
}

// One answer per command: an optional data line, then ACK:/NAK: for a framed line
// with a sequence number, ERR: for any other rejected command. At most
// WC_ERR_LINES_PER_TICK commands are answered per tick; the rest are counted.
static void answer(ParseResult r, int32_t seq, uint8_t data) {
  if (errLinesThisTick >= WC_ERR_LINES_PER_TICK) {
    errSuppressed++;
    return;
  }
  errLinesThisTick++;
  if (r == PARSE_OK && data == DATA_HELLO) {
    line.print(F("HELLO:"));
    line.print(linesFramed ? WC_PROTOCOL_VERSION : WC_PROTOCOL_VERSION_PLAIN);
    line.print(F(",final_control," WC_FIRMWARE_VERSION ","));
    line.print(F(WC_BUILD_ID));
    line.print(',');
    line.println(profile);             // the drive profile in force
    line.send();
  } else if (r == PARSE_OK && data == DATA_PARAM) {
    line.print(F("PAR:"));
    line.print((const __FlashStringHelper*)PARAM_NAMES[replyParam]);
    line.print(',');
    if (replyParam == PARAM_WATCHDOG) {
      line.println(watchdogMs);
    } else if (replyParam == PARAM_FEEDBACK_FORM) {
      line.println(feedbackForm);
    } else if (replyParam == PARAM_BRAKE_FITTED) {
      line.println(brakeFitted);
    } else if (replyParam == PARAM_PROFILE) {
      line.println(profile);
    } else {
      line.println(*PARAM_VARS[replyParam], 4);
    }
    line.send();
  }
  if (seq >= 0) {
    line.print(r == PARSE_OK ? F("ACK:") : F("NAK:"));
    line.print((uint16_t)seq);
    if (r != PARSE_OK) {
      line.print(',');
      line.print((const __FlashStringHelper*)REASONS[r]);
    }
    line.println();
    line.send();
  } else if (r != PARSE_OK) {
    line.print(F("ERR:"));
    line.println((const __FlashStringHelper*)REASONS[r]);
    line.send();
  }
}

static void reject(ParseResult why) {
  rejectedCount++;
  answer(why, -1, DATA_NONE);
}

// Splits the command at its commas (replaced by NULs). Returns the number of
// fields; a trailing comma does not open another field.
static uint8_t splitFields(char* fields[], uint8_t maxFields) {
  uint8_t n = 0;
  char* p = cmdBuf;
  char* end = cmdBuf + cmdLen;
  while (p < end) {
    if (n == maxFields) return maxFields + 1;
    fields[n++] = p;
    while (p < end && *p != ',') p++;
    if (p < end) *p++ = '\0';
  }
  return n;
}

// Bounds strtod's work before it runs: it walks every digit and scales by one float
// multiplication per 10^32 of exponent, so "1e-31999" took 6.5 ms. A number has at
// most WC_NUMBER_MAX_DIGITS digits before its exponent (leading zeros count; else
// ERR_NUMBER) and at most WC_NUMBER_MAX_EXP_DIGITS exponent digits (else ERR_RANGE).
// Anything else (junk, a second point, no digit, inf, nan) is left to strtod, which
// stops at it at once.
static ParseResult numberInReach(const char* s) {
  if (*s == '+' || *s == '-') s++;
  uint8_t digits = 0;
  bool point = false;
  for (;; s++) {
    if (*s >= '0' && *s <= '9') {
      if (++digits > WC_NUMBER_MAX_DIGITS) return ERR_NUMBER;
    } else if (*s == '.' && !point) {
      point = true;
    } else {
      break;
    }
  }
  if (digits == 0 || (*s != 'e' && *s != 'E')) return PARSE_OK;
  s++;
  if (*s == '+' || *s == '-') s++;
  for (uint8_t n = 0; *s >= '0' && *s <= '9'; s++) {
    if (++n > WC_NUMBER_MAX_EXP_DIGITS) return ERR_RANGE;
  }
  return PARSE_OK;
}

// A decimal number through avr-libc strtod, the whole field consumed.
static ParseResult parseNumber(const char* s, bool allowSign, float& value) {
  char c = s[0];
  bool digitOrPoint = (c >= '0' && c <= '9') || c == '.';
  if (!digitOrPoint && !(allowSign && (c == '+' || c == '-'))) return ERR_NUMBER;
  ParseResult reach = numberInReach(s);
  if (reach != PARSE_OK) return reach;
  char* end;
  value = (float)strtod(s, &end);
  if (end == s || *end != '\0') return ERR_NUMBER;
  return PARSE_OK;
}

static ParseResult parseBounded(const char* s, bool allowSign, float max, float& value) {
  ParseResult r = parseNumber(s, allowSign, value);
  if (r != PARSE_OK) return r;
  if (!(value >= -max && value <= max)) return ERR_RANGE;   // also catches inf and NaN
  return PARSE_OK;
}

// 1 to 4 (or 5) decimal digits and nothing else; -1 when it is not.
static int32_t parseDigits(const char* s, uint8_t maxDigits) {
  int32_t v = 0;
  uint8_t n = 0;
  for (; *s; s++, n++) {
    if (*s < '0' || *s > '9' || n == maxDigits) return -1;
    v = v * 10 + (*s - '0');
  }
  return n == 0 ? -1 : v;
}

// After hello, a line that is not a v3 frame may only make the chair safer: a zero
// velocity in any form (or estop, or a PPM frame that reports signal loss).
static bool refusedUnframed(float right, float left) {
  return unframedLine && (right != 0.0f || left != 0.0f);
}

// While the board waits for neutral (needNeutral), a motion command is refused and
// restarts the wait (EVT:NOT_NEUTRAL, once a wait, from the next tick); a neutral one
// starts the count the tick confirms.
static bool refusedNotNeutral(float right, float left) {
  if (!needNeutral) return false;
  if (right != 0.0f || left != 0.0f) {
    neutralSeen = false;
    if (!notNeutralSent) {
      notNeutralSent = true;
      notNeutralPending = true;
    }
    return true;
  }
  if (!neutralSeen) {
    neutralSeen = true;
    neutralTicks = 0;
  }
  notNeutralTicks = 0;
  return false;
}

// The gate of every motion command (WHEEL, CMDVEL, PPM): PARSE_OK and take true to
// drive, or why not. With the e-stop latched or a fault a stop is accepted and changes
// nothing (take false); anything else is refused.
static ParseResult gateMotion(float right, float left, bool& take) {
  take = false;
  bool stop = right == 0.0f && left == 0.0f;
  if (refusedUnframed(right, left)) return ERR_UNFRAMED;
  if (estopLatched) return stop ? PARSE_OK : ERR_ESTOP;
  if (faultFlags != 0) return stop ? PARSE_OK : ERR_FAULT;
  if (limitLatched) {
    if (!stop) return ERR_LIMIT;
    limitLatched = false;   // a stop: the host has seen the limit, and what it sends next drives
  }
  if (!stop && (inhibitEngaged() & INHIBIT_STOP_MASK)) return ERR_INHIBIT;
  if (refusedNotNeutral(right, left)) return ERR_NEUTRAL;
  take = true;
  return PARSE_OK;
}

// A motion command: the wheel targets, if the gate lets it through.
static ParseResult moveTo(uint8_t newMode, float right, float left) {
  bool take;
  ParseResult r = gateMotion(right, left, take);
  if (take) acceptCommand(newMode, right, left);
  return r;
}

// rp5.0,lp3.0,  (p/n give the sign)
static ParseResult parseWheel() {
  char* f[2];
  if (splitFields(f, 2) != 2) return ERR_FIELDS;
  if (f[0][0] != 'r' || f[1][0] != 'l') return ERR_SYNTAX;
  float v[2];
  for (uint8_t i = 0; i < 2; i++) {
    char sign = f[i][1];
    if (sign != 'p' && sign != 'n') return ERR_SYNTAX;
    ParseResult r = parseBounded(f[i] + 2, false, maxWheel, v[i]);
    if (r != PARSE_OK) return r;
    if (sign == 'n') v[i] = -v[i];
  }
  return moveTo(WC_MODE_WHEEL, v[0], v[1]);
}

// x:0.5,t:0.1,  (m/s, rad/s; seed section 1.7)
static ParseResult parseCmdVel() {
  char* f[2];
  if (splitFields(f, 2) != 2) return ERR_FIELDS;
  if (f[0][0] != 'x' || f[0][1] != ':' || f[1][0] != 't' || f[1][1] != ':') return ERR_SYNTAX;
  float x, t;
  ParseResult r = parseBounded(f[0] + 2, true, WC_MAX_LINEAR, x);
  if (r != PARSE_OK) return r;
  r = parseBounded(f[1] + 2, true, WC_MAX_ANGULAR, t);
  if (r != PARSE_OK) return r;
  float right = (x + t * WC_WHEELBASE / 2.0f) / WC_WHEEL_RADIUS;
  float left = (x - t * WC_WHEELBASE / 2.0f) / WC_WHEEL_RADIUS;
  float peak = fabs(right) > fabs(left) ? fabs(right) : fabs(left);
  if (peak > maxWheel) {   // keep the curvature, cap the faster wheel
    float k = maxWheel / peak;
    right *= k;
    left *= k;
  }
  return moveTo(WC_MODE_CMDVEL, right, left);
}

static int16_t shapeStick(int16_t us) {
  if (us >= -WC_PPM_DEADBAND && us <= WC_PPM_DEADBAND) return 0;
  return constrain(us, -WC_PPM_SPAN, WC_PPM_SPAN);
}

// ppm:c1,...,c8,  (pulse widths in us; seed section 1.5.3)
static ParseResult parsePpm() {
  if (cmdBuf[3] != ':') return ERR_SYNTAX;
  cmdBuf[3] = ',';   // "ppm:" becomes a first field of its own
  char* f[WC_PPM_CHANNELS + 1];
  if (splitFields(f, WC_PPM_CHANNELS + 1) != WC_PPM_CHANNELS + 1) return ERR_FIELDS;
  int16_t ch[WC_PPM_CHANNELS];
  bool lost = false;
  for (uint8_t i = 0; i < WC_PPM_CHANNELS; i++) {
    int32_t v = parseDigits(f[i + 1], 4);
    if (v < 0) return ERR_NUMBER;
    ch[i] = (int16_t)v;
    if (v < WC_PPM_VALID_MIN || v > WC_PPM_VALID_MAX) lost = true;
  }
  if (lost) {
    if (estopLatched || faultFlags != 0) return PARSE_OK;   // stopped already
    mode = WC_MODE_PPM;
    cmdSinceTick = true;
    emergencyHalt();
    requireNeutral();   // the transmitter back: its stick must come to neutral first
    if (!ppmLost) sendEvent(F("PPM_LOST"));
    ppmLost = true;
    return PARSE_OK;
  }
  float perUs = WC_PPM_MAX_WHEEL / WC_PPM_SPAN;
  float cap = maxWheel < WC_PPM_MAX_WHEEL ? maxWheel : WC_PPM_MAX_WHEEL;
  float fwd = (float)shapeStick(ch[WC_PPM_FWD_CHANNEL] - WC_PPM_NEUTRAL) * perUs;
  float turn = (float)shapeStick(ch[WC_PPM_TURN_CHANNEL] - WC_PPM_NEUTRAL) * perUs;
  float right = constrain(fwd - turn, -cap, cap);
  float left = constrain(fwd + turn, -cap, cap);
  bool take;
  ParseResult r = gateMotion(right, left, take);
  if (take) {
    ppmLost = false;
    acceptCommand(WC_MODE_PPM, right, left);
  }
  return r;
}

// estop: stop at the emergency rate and refuse motion until "reset".
static ParseResult latchEstop() {
  emergencyHalt();
  cmdSinceTick = false;
  watchdogArmed = false;       // stopped on purpose: no watchdog event on top
  if (!estopLatched) sendEvent(F("ESTOP"));
  estopLatched = true;
  return PARSE_OK;
}

// reset: release the e-stop and any fault once the chair is parked (at rest, motors
// off); encoders masked by the storm guard come back (those whose storm a tick latched).
static ParseResult resetEstop() {
  if ((estopLatched || faultFlags != 0) && !parked) return ERR_BUSY;
  if (estopLatched || faultFlags != 0) requireNeutral();
  inhibitLatched &= inhibitStable;   // a latched inhibit whose input is released ends (next tick)
  estopLatched = false;
  if (faultFlags != 0) holding = false;   // the hold restarts with both wheels, where they are
  faultFlags = 0;
  unmaskEncoders();
  return PARSE_OK;
}

static int8_t findParam(const char* name) {
  for (uint8_t i = 0; i < PARAM_COUNT; i++) {
    if (strcmp_P(name, PARAM_NAMES[i]) == 0) return (int8_t)i;
  }
  return -1;
}

// get:<name>
static ParseResult parseGet(uint8_t& data) {
  int8_t i = findParam(cmdBuf + 4);
  if (i < 0) return ERR_PARAM;
  replyParam = (uint8_t)i;
  data = DATA_PARAM;
  return PARSE_OK;
}

// set:<name>=<value>
static ParseResult parseSet(uint8_t& data) {
  char* eq = strchr(cmdBuf + 4, '=');
  if (eq == NULL) return ERR_SYNTAX;
  *eq = '\0';
  int8_t i = findParam(cmdBuf + 4);
  if (i < 0) return ERR_PARAM;
  if (i == PARAM_WATCHDOG) {
    int32_t ms = parseDigits(eq + 1, 4);
    if (ms < 0) return ERR_NUMBER;
    if (ms < WC_WATCHDOG_MIN_MS || ms > WC_WATCHDOG_MAX_MS) return ERR_RANGE;
    watchdogMs = (uint16_t)ms;
  } else if (i == PARAM_FEEDBACK_FORM) {
    int32_t form = parseDigits(eq + 1, 4);
    if (form < 0) return ERR_NUMBER;
    if (form > WC_FEEDBACK_FORM_MAX) return ERR_RANGE;
    feedbackForm = (uint8_t)form;
  } else if (i == PARAM_BRAKE_FITTED) {
    int32_t fitted = parseDigits(eq + 1, 4);
    if (fitted < 0) return ERR_NUMBER;
    if (fitted > WC_BRAKE_FITTED_MAX) return ERR_RANGE;
    brakeFitted = (uint8_t)fitted;
    // the brake's phase from its pin: released, or engaging (it may not hold yet)
    brakePhase = brakeReleased ? BRAKE_RELEASED : BRAKE_ENGAGING;
    brakeTicks = 0;
    brakeStatusTicks = 0;
  } else if (i == PARAM_PROFILE) {
    int32_t p = parseDigits(eq + 1, 4);
    if (p < 0) return ERR_NUMBER;
    if (p > WC_PROFILE_MAX) return ERR_RANGE;
    useProfile((uint8_t)p);
  } else {
    float v;
    ParseResult r = parseNumber(eq + 1, false, v);
    if (r != PARSE_OK) return r;
    if (!(v >= PARAM_MIN[i] && v <= PARAM_MAX[i])) return ERR_RANGE;
    *PARAM_VARS[i] = v;
    // a drive limit: the profile in force's, its row changed with it
    if (i >= PARAM_DRIVE_FIRST && i < PARAM_DRIVE_FIRST + PROFILE_FLOATS) {
      profileTable[profile][i - PARAM_DRIVE_FIRST] = v;
    }
  }
  replyParam = (uint8_t)i;
  data = DATA_PARAM;
  return PARSE_OK;
}

// ---------------------------------------------------------------------------
// Parameters in EEPROM (protocol/PROTOCOL.md, "Parameters in EEPROM"). The block at
// WC_EEPROM_PARAMS_ADDR: the layout version (WC_EEPROM_LAYOUT), the 10 float parameters
// before the drive limits in table order (binary32, little-endian), the drive profiles'
// table (WC_PROFILE_COUNT rows of PROFILE_FLOATS), watchdog_ms (uint16), feedback_form,
// brake_fitted and profile (uint8 each), then the CRC-16/XMODEM of those 174 bytes
// (uint16, little-endian): 176 bytes.
// ---------------------------------------------------------------------------
#define EE_TABLE_AT (1 + 4 * PARAM_DRIVE_FIRST)
#define EE_WATCHDOG_AT (EE_TABLE_AT + (int)sizeof(profileTable))
#define EE_FORM_AT (EE_WATCHDOG_AT + 2)
#define EE_FITTED_AT (EE_FORM_AT + 1)
#define EE_PROFILE_AT (EE_FITTED_AT + 1)
#define EE_DATA_BYTES (EE_PROFILE_AT + 1)
#define EE_BLOCK_BYTES (EE_DATA_BYTES + 2)
// What save writes. In .noinit, as profileTable: save fills it before anything reads it.
static uint8_t eeBlock[EE_BLOCK_BYTES] __attribute__((section(".noinit")));
uint8_t eeNext = EE_BLOCK_BYTES;          // the next byte of eeBlock to compare and write
uint8_t eeBusy = 0;                       // a save is being written (the interrupt is on)

static uint16_t eeCrc(const uint8_t* b) {
  uint16_t crc = 0;
  for (uint8_t i = 0; i < EE_DATA_BYTES; i++) crc = _crc_xmodem_update(crc, b[i]);
  return crc;
}

// Writes the next byte of eeBlock that differs from the EEPROM and arms the EEPROM-ready
// interrupt, which comes back here when that write is done (3.4 ms on the chip): one
// byte per interrupt, so neither loop() nor an interrupt ever waits for the EEPROM.
// Once every byte matches, the interrupt is turned off: the last write is done, so the
// EEPROM is free for the next save (the chip ignores a write while one is in progress).
static inline __attribute__((always_inline)) void eeWriteNext() {
  while (eeNext < EE_BLOCK_BYTES &&
         eeprom_read_byte((const uint8_t*)(WC_EEPROM_PARAMS_ADDR + eeNext)) == eeBlock[eeNext]) {
    eeNext++;
  }
  if (eeNext == EE_BLOCK_BYTES) {
    EECR &= (uint8_t)~_BV(EERIE);
    eeBusy = 0;
    return;
  }
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    EEAR = WC_EEPROM_PARAMS_ADDR + eeNext;
    EEDR = eeBlock[eeNext];
    EECR |= _BV(EEMPE);     // EEPE within 4 cycles of EEMPE
    EECR |= _BV(EEPE);
  }
  eeNext++;
  eeBusy = 1;
  EECR |= _BV(EERIE);
}

// The EEPROM-ready interrupt. Not inlined: the lock-step harness stops at its entry.
extern "C" __attribute__((noinline)) void eepromReady() { eeWriteNext(); }
// The interrupt is level-triggered (EEPE clear and EERIE set): off first, then the
// other interrupts back on, so that the encoders' are never held for the ~150 cycles
// this one takes (merged edges at top speed otherwise).
ISR(EE_READY_vect) {
  EECR &= (uint8_t)~_BV(EERIE);
  sei();
  eepromReady();
}

// save: the parameters in force into the EEPROM, written in the background; refused
// (busy) while the last save is still being written.
static ParseResult saveParams() {
  if (eeBusy) return ERR_BUSY;
  eeBlock[0] = WC_EEPROM_LAYOUT;
  for (uint8_t i = 0; i < PARAM_DRIVE_FIRST; i++) memcpy(eeBlock + 1 + 4 * i, PARAM_VARS[i], 4);
  memcpy(eeBlock + EE_TABLE_AT, profileTable, sizeof(profileTable));
  memcpy(eeBlock + EE_WATCHDOG_AT, &watchdogMs, 2);
  eeBlock[EE_FORM_AT] = feedbackForm;
  eeBlock[EE_FITTED_AT] = brakeFitted;
  eeBlock[EE_PROFILE_AT] = profile;
  uint16_t crc = eeCrc(eeBlock);
  memcpy(eeBlock + EE_DATA_BYTES, &crc, 2);
  eeNext = 0;
  eeWriteNext();
  return PARSE_OK;
}

// defaults: the parameters back to the firmware's defaults (the EEPROM is not written:
// a save after it stores them).
static ParseResult restoreDefaults() {
  kpL = WC_KP_L; kiL = WC_KI_L; kdL = WC_KD_L;
  kpR = WC_KP_R; kiR = WC_KI_R; kdR = WC_KD_R;
  maxWheel = WC_MAX_WHEEL_SPEED;
  maxAccel = WC_MAX_ACCEL;
  estopDecel = WC_EMERGENCY_DECEL;
  stallTimeout = WC_STALL_TIMEOUT;
  presetProfiles();
  useProfile(WC_PROFILE);
  watchdogMs = WC_WATCHDOG_MS;
  feedbackForm = WC_FEEDBACK_FORM;
  // brake_fitted stays: it says what the chair has, not how it is tuned
  return PARSE_OK;
}

// At boot: the saved parameters if the block is whole (version, CRC, every value in its
// range; EVT:PARAMS_LOADED), else the defaults stay (EVT:PARAMS_DEFAULT,<why>).
static void loadParams() {
  uint8_t b[EE_BLOCK_BYTES];
  eeprom_read_block(b, (const void*)WC_EEPROM_PARAMS_ADDR, EE_BLOCK_BYTES);
  const __FlashStringHelper* why = NULL;
  bool blank = true;
  for (uint8_t i = 0; i < EE_BLOCK_BYTES; i++) {
    if (b[i] != 0xFF) blank = false;
  }
  uint16_t crc;
  memcpy(&crc, b + EE_DATA_BYTES, 2);
  uint16_t ms;
  memcpy(&ms, b + EE_WATCHDOG_AT, 2);
  if (blank) {
    why = F("blank");
  } else if (b[0] != WC_EEPROM_LAYOUT) {
    why = F("version");
  } else if (crc != eeCrc(b)) {
    why = F("crc");
  } else if (ms < WC_WATCHDOG_MIN_MS || ms > WC_WATCHDOG_MAX_MS || b[EE_FORM_AT] > WC_FEEDBACK_FORM_MAX ||
             b[EE_FITTED_AT] > WC_BRAKE_FITTED_MAX || b[EE_PROFILE_AT] > WC_PROFILE_MAX) {
    why = F("range");
  } else {
    for (uint8_t i = 0; i < PARAM_DRIVE_FIRST + PROFILE_FLOATS * WC_PROFILE_COUNT; i++) {
      // the floats before the drive limits, then the table's, row by row
      uint8_t param = i < PARAM_DRIVE_FIRST ? i : PARAM_DRIVE_FIRST + (i - PARAM_DRIVE_FIRST) % PROFILE_FLOATS;
      float v;
      memcpy(&v, b + 1 + 4 * i, 4);
      if (!(v >= PARAM_MIN[param] && v <= PARAM_MAX[param])) why = F("range");   // NaN too
    }
  }
  if (why == NULL) {
    for (uint8_t i = 0; i < PARAM_DRIVE_FIRST; i++) memcpy(PARAM_VARS[i], b + 1 + 4 * i, 4);
    memcpy(profileTable, b + EE_TABLE_AT, sizeof(profileTable));
    useProfile(b[EE_PROFILE_AT]);
    watchdogMs = ms;
    feedbackForm = b[EE_FORM_AT];
    brakeFitted = b[EE_FITTED_AT];   // at boot: the brake engaged from reset (BRAKE_ENGAGED)
    sendEvent(F("PARAMS_LOADED"));
  } else {
    line.print(F("EVT:PARAMS_DEFAULT,"));
    line.println(why);
    line.send();
  }
}

// Which command the buffer holds, by its first bytes: the number of fields it
// takes, or 0 when no command starts that way.
static uint8_t fieldsExpected() {
  if (cmdBuf[0] == 'r' || cmdBuf[0] == 'x') return 2;
  if (cmdLen >= 4 && cmdBuf[0] == 'p' && cmdBuf[1] == 'p' && cmdBuf[2] == 'm' && cmdBuf[3] == ':') {
    return WC_PPM_CHANNELS;
  }
  return 0;
}

// Commands are printable ASCII without spaces: a control byte, a NUL (which
// would end a field early for strtod) or a byte with the top bit set is junk.
static bool allPrintable() {
  for (uint8_t i = 0; i < cmdLen; i++) {
    uint8_t c = (uint8_t)cmdBuf[i];
    if (c <= ' ' || c >= 0x7F) return false;
  }
  return true;
}

// An upper-case hex digit's value, or -1.
static int8_t hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// A v3 frame: $<seq>:<command>*<CCCC>, CCCC the CRC-16/XMODEM of the bytes between
// $ and * in upper-case hex. Checks the CRC, takes the sequence number (mandatory)
// and leaves the bare command in cmdBuf.
static ParseResult unframe(int32_t& seq) {
  if (cmdLen < 6 || cmdBuf[cmdLen - 5] != '*') return ERR_CHECKSUM;
  uint16_t sent = 0;
  for (uint8_t i = cmdLen - 4; i < cmdLen; i++) {
    int8_t h = hexValue(cmdBuf[i]);
    if (h < 0) return ERR_CHECKSUM;
    sent = (sent << 4) | (uint8_t)h;
  }
  uint16_t crc = 0;
  for (uint8_t i = 1; i < cmdLen - 5; i++) crc = _crc_xmodem_update(crc, (uint8_t)cmdBuf[i]);
  if (crc != sent) return ERR_CHECKSUM;
  int32_t v = 0;
  uint8_t p = 1;
  while (cmdBuf[p] >= '0' && cmdBuf[p] <= '9') {
    if (p == 6) return ERR_SYNTAX;            // more than 5 digits
    v = v * 10 + (cmdBuf[p] - '0');
    p++;
  }
  if (p == 1 || cmdBuf[p] != ':' || v > (int32_t)WC_SEQ_MAX) return ERR_SYNTAX;
  seq = v;
  lastSeq = (uint16_t)v;
  uint8_t start = p + 1;
  cmdLen = cmdLen - 5 - start;
  memmove(cmdBuf, cmdBuf + start, cmdLen);
  cmdBuf[cmdLen] = '\0';
  return PARSE_OK;
}

static ParseResult dispatch(uint8_t& data) {
  if (!allPrintable()) return ERR_SYNTAX;
  if (strcmp_P(cmdBuf, PSTR("estop")) == 0) return latchEstop();
  if (cmdBuf[0] == 'x') return parseCmdVel();        // unframed: zero only (moveTo)
  if (cmdBuf[0] == 'r' && cmdBuf[1] != 'e') return parseWheel();
  if (cmdLen >= 4 && cmdBuf[0] == 'p' && cmdBuf[1] == 'p' && cmdBuf[2] == 'm') return parsePpm();
  if (unframedLine) return ERR_UNFRAMED;              // after hello, nothing else unframed
  if (strcmp_P(cmdBuf, PSTR("hello")) == 0 || strcmp_P(cmdBuf, PSTR("hello:4")) == 0) {
    tlmEnabled = true;      // TLM lines from now on, and v3 frames only until reset
    linesFramed = cmdBuf[5] == ':';   // hello:4: protocol v4, the board's lines framed
    data = DATA_HELLO;
    return PARSE_OK;
  }
  if (strcmp_P(cmdBuf, PSTR("reset")) == 0) return resetEstop();
  if (strncmp_P(cmdBuf, PSTR("get:"), 4) == 0) return parseGet(data);
  if (strncmp_P(cmdBuf, PSTR("set:"), 4) == 0) return parseSet(data);
  if (strcmp_P(cmdBuf, PSTR("save")) == 0) return saveParams();
  if (strcmp_P(cmdBuf, PSTR("defaults")) == 0) return restoreDefaults();
  if (cmdBuf[0] == 'r') return parseWheel();
  return ERR_SYNTAX;
}

static void finishCommand() {
  cmdBuf[cmdLen] = '\0';
  int32_t seq = -1;
  uint8_t data = DATA_NONE;
  ParseResult r = PARSE_OK;
  unframedLine = false;
  if (cmdBuf[0] == '$') {
    r = unframe(seq);
    if (r == ERR_CHECKSUM) crcRejected++;
  } else if (tlmEnabled) {
    unframedLine = true;    // after hello: only what makes the chair safer
  }
  if (r == PARSE_OK) r = dispatch(data);
  if (r != PARSE_OK) rejectedCount++;
  if (r != PARSE_OK || seq >= 0 || data != DATA_NONE) answer(r, seq, data);
  cmdLen = 0;
  cmdCommas = 0;
}

// Bytes were lost before the next one (loop() found losses counted at its ring slot,
// "lost": bytes dropped for a full ring, one per overrun): the command being received
// lost a byte, so it is thrown away, and so is what follows up to the next ',' or line
// end (the lost bytes may have held a line end: the two pieces must not join into one
// command). The discard ends with ERR:overrun. Not inlined: the lock-step harness stops
// at its entry, as at processByte's, and reads "lost".
extern "C" __attribute__((noinline)) void rxGap(uint8_t lost) {
  rxGaps += lost;
  cmdLen = 0;
  cmdCommas = 0;
  cmdDiscarding = DISCARD_OVERRUN;
}

extern "C" __attribute__((noinline)) void processByte(uint8_t c) {
  rxCount++;
  if (c == '\n' || c == '\r') {
    if (cmdDiscarding == DISCARD_OVERRUN) {
      cmdDiscarding = DISCARD_NONE;
      reject(ERR_OVERRUN);
    } else if (cmdDiscarding != DISCARD_NONE) {
      cmdDiscarding = DISCARD_NONE;
    } else if (cmdLen > 0) {
      finishCommand();
    }
    return;
  }
  if (cmdDiscarding != DISCARD_NONE) {
    if (c == ',' && cmdDiscarding == DISCARD_OVERRUN) {
      cmdDiscarding = DISCARD_NONE;
      reject(ERR_OVERRUN);
    } else if (c == ',' && cmdDiscarding == DISCARD_TO_COMMA) {
      cmdDiscarding = DISCARD_NONE;
    }
    return;
  }
  if (cmdLen >= WC_CMD_MAX_LEN) {
    reject(ERR_OVERLONG);
    if (cmdBuf[0] == '$') {
      cmdDiscarding = DISCARD_TO_EOL;
    } else {
      cmdDiscarding = c == ',' ? DISCARD_NONE : DISCARD_TO_COMMA;
    }
    cmdLen = 0;
    cmdCommas = 0;
    return;
  }
  cmdBuf[cmdLen++] = (char)c;
  if (c != ',' || cmdBuf[0] == '$') return;   // a framed line ends at its line end only
  cmdCommas++;
  uint8_t expected = fieldsExpected();
  if (expected == 0) {
    reject(tlmEnabled ? ERR_UNFRAMED : ERR_SYNTAX);
    cmdLen = 0;
    cmdCommas = 0;
  } else if (cmdCommas >= expected) {
    finishCommand();   // the seed host's newline-less form ends at the last comma
  }
}

// ---------------------------------------------------------------------------
// Reset cause: MCUSR, read and cleared before anything else runs (.init3), and the
// hardware watchdog off until setup() arms it (after a watchdog reset it stays on at
// its shortest period, which would reset the board again in the middle of setup()).
uint8_t resetCause __attribute__((section(".noinit")));
extern "C" void captureResetCause() __attribute__((naked, used, section(".init3")));
extern "C" void captureResetCause() {
  resetCause = MCUSR;
  MCUSR = 0;
  wdt_disable();
}

// The BOOT line's cause word, the first of MCUSR's flags that is set.
static const __FlashStringHelper* resetCauseName(uint8_t mcusr) {
  if (mcusr & _BV(WDRF)) return F("WATCHDOG");
  if (mcusr & _BV(BORF)) return F("BROWN_OUT");
  if (mcusr & _BV(EXTRF)) return F("EXTERNAL");
  if (mcusr & _BV(PORF)) return F("POWER_ON");
  if (mcusr & _BV(JTRF)) return F("JTAG");
  return F("NONE");
}

// ---------------------------------------------------------------------------
void setup() {
  pinMode(WC_PIN_RELAY, OUTPUT);
  digitalWrite(WC_PIN_RELAY, LOW);
  pinMode(WC_PIN_BRAKE, OUTPUT);
  digitalWrite(WC_PIN_BRAKE, LOW);
  pinMode(WC_PIN_DIR_L, OUTPUT);
  pinMode(WC_PIN_DIR_R, OUTPUT);
  pinMode(WC_PIN_PWM_L, OUTPUT);
  pinMode(WC_PIN_PWM_R, OUTPUT);
  setMotor(WC_PIN_PWM_L, WC_PIN_DIR_L, 0.0f, pwmL, dirL);
  setMotor(WC_PIN_PWM_R, WC_PIN_DIR_R, 0.0f, pwmR, dirR);
  pinMode(WC_PIN_INHIBIT_1, INPUT_PULLUP);
  pinMode(WC_PIN_INHIBIT_2, INPUT_PULLUP);
  pinMode(WC_PIN_BRAKE_STATUS, INPUT_PULLUP);
  pinMode(WC_PIN_PUSH, INPUT_PULLUP);
  pinMode(WC_PIN_ENC_L_A, INPUT);
  pinMode(WC_PIN_ENC_L_B, INPUT);
  pinMode(WC_PIN_ENC_R_A, INPUT);
  pinMode(WC_PIN_ENC_R_B, INPUT);
  // The supply sense: ADC0 (MUX5 clear) against AVcc, the ADC clock at 125 kHz, the
  // analog pins' digital buffers off; the first conversion, which the first tick reads.
  ADMUX = _BV(REFS0) | (WC_PIN_SUPPLY & 7);
  ADCSRB &= (uint8_t)~_BV(MUX5);
  DIDR0 = _BV(WC_PIN_SUPPLY) | _BV(WC_PIN_CURRENT_L) | _BV(WC_PIN_CURRENT_R);
  ADCSRA = _BV(ADEN) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);
  ADCSRA |= _BV(ADSC);

  wcSerial.begin(WC_BAUD);

  GPIOR1 = (uint8_t)(readEncoderL() << 2);
  GPIOR2 = (uint8_t)(readEncoderR() << 2);
  // Any edge on INT2..INT5 (both channels of both encoders).
  EICRA = (EICRA & 0x0F) | _BV(ISC20) | _BV(ISC30);
  EICRB = (EICRB & 0xF0) | _BV(ISC40) | _BV(ISC50);
  EIFR = _BV(INTF2) | _BV(INTF3) | _BV(INTF4) | _BV(INTF5);
  EIMSK |= _BV(INT2) | _BV(INT3) | _BV(INT4) | _BV(INT5);
  // The storm guard's window: Timer0 (millis(), 1.024 ms per period) matching OCR0A once
  // a period. OC0A (pin 13) stays disconnected: no PWM is written there.
  OCR0A = WC_STORM_COMPARE;
  TIFR0 = _BV(OCF0A);
  TIMSK0 |= _BV(OCIE0A);

  digitalWrite(WC_PIN_RELAY, HIGH);
  line.print(F("BOOT:final_control,"));
  line.println(resetCauseName(resetCause));
  line.send();
  // The budget starts after the BOOT line: WC_TX_CREDIT_BOOT leaves the ring room for it.
  // Sends move credit into the ring and the UART drains it faster than the credit
  // refills, so the ring's bytes and the credit add up to no more than now, or than
  // WC_TX_CREDIT_MAX once the ring is empty, and the 2 ms by which millis() may run
  // ahead of the UART between two ticks: the ring never holds more than 511.
  txCredit = WC_TX_CREDIT_BOOT;
  presetProfiles();             // the table's rows before a saved block replaces them
  loadParams();                 // and its EVT line, within the budget
  wdt_enable(WC_HW_WATCHDOG);   // a loop() pass that hangs resets the board
  lastControlTime = lastTickTime = millis();
}

// Bytes between the top of the heap and the stack pointer, as loop() runs.
static uint16_t measureFreeRam() {
  extern char __heap_start;
  extern char* __brkval;
  char top;
  return (uint16_t)(&top - (__brkval != 0 ? __brkval : &__heap_start));
}

void loop() {
  wdt_reset();
  // Bounded: at most one RX buffer's worth per pass.
  for (uint8_t n = 0; n < SERIAL_RX_BUFFER_SIZE; n++) {
    uint8_t lost = 0;
    int c = wcSerial.readMarked(lost);
    if (c < 0) break;
    if (lost) rxGap(lost);
    processByte((uint8_t)c);
  }
  uint32_t now = millis();
  if (now - lastControlTime >= WC_CONTROL_PERIOD_MS) {
    freeRam = measureFreeRam();
    controlTick(now);
  }
}
