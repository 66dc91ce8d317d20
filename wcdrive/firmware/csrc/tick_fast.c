/*
 * tick_fast: the common case of the port's control tick (wcdrive.firmware.control's
 * control_tick) as a CPython extension, for speed: the simulation runs the tick 20
 * times a simulated second, and in Python it is about a fifth of a run's time.
 *
 * tick(state, now, count_l, count_r, illegal_l, illegal_r, storm_l, storm_r, rx_lost,
 * inputs, supply, current_l, current_r) computes what control_tick(state, now, ..., out, ...) computes and returns the bytes
 * it would append to ``out``, or returns None having changed nothing. It returns None
 * (and the Python tick, the reference, runs instead) for everything but the common
 * case:
 *   - a state that is not exactly a FirmwareState, or a field that is not exactly a
 *     float or an int (or an int beyond +-2**62);
 *   - any binary32 operation whose result is not an ordinary one (NaN, an infinity, a
 *     product below 2**-126, a quotient below 2**-125, a division by zero): the cases
 *     wcdrive.avr.f32 computes with avr-libc's own bit-level rules;
 *   - a tick in which a fault latches, a wheel's check trips at all (a fault or the
 *     chair's limit), an overspeed parks the chair or the watchdog fires (they send
 *     events and halt);
 *   - a tick while the board waits for neutral (needNeutral: after a boot, a reset, a
 *     watchdog stop or a PPM loss, a few ticks at most while a host is well behaved);
 *   - a tick with an inhibit input (the brake's manual release too) read active,
 *     engaged, debouncing or with its event still to send;
 *   - with a brake fitted (brakeFitted), a tick that parks, finds the brake other than
 *     released and settled (its phase, wcdrive.firmware.brake) or reads its driver's
 *     status LOW;
 *   - a wheel within STALL_CREEP_COUNTS whose motor's current sense reads STALL_CURRENT
 *     or more (it may be held at its current limit, the stall clock may run), or a
 *     sense past CURRENT_SENSE_MAX (failed);
 *   - a mode that MODE_NAMES does not name.
 * Each binary32 operation is one IEEE double operation rounded once to binary32, as
 * f32.py (and f32_fast.c) computes the ordinary case. The whole tick is computed into
 * locals first and the state written only at the end, so declining is always clean.
 *
 * The constants, the mode names and FirmwareState's slot offsets come from Python at
 * _bind() (wcdrive.firmware.tick_fast), so nothing here restates the spec.
 * tests/firmware/test_tick_fast.py holds this to the Python tick on random states and
 * on whole runs; the differential suite holds the port (this path by default) to the
 * firmware.
 * Built at install (setup.py's NATIVE) or else on first use by wcdrive._util.native
 * (gcc -O2 -ffp-contract=off).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <math.h>
#include <float.h>
#include <stdint.h>
#include <string.h>

/* ---- binary32 operations: the ordinary case, or "not ordinary" (ok = 0) ---------- */

static int ok;          /* cleared by an operation whose result is not ordinary */

static double rnd(double r) {
    float f = (float)r;
    if (!isfinite(f))
        ok = 0;
    return (double)f;
}
static double f_add(double a, double b) { return rnd(a + b); }
static double f_sub(double a, double b) { return rnd(a - b); }
static double f_mul(double a, double b) {
    double p = a * b;
    if (isnan(p) || (p != 0.0 && fabs(p) < (double)FLT_MIN)) {
        ok = 0;
        return 0.0;
    }
    return rnd(p);
}
static double f_div(double a, double b) {
    if (b == 0.0) {
        ok = 0;
        return 0.0;
    }
    double q = a / b;
    if (isnan(q) || (q != 0.0 && fabs(q) < 2.0 * (double)FLT_MIN)) {
        ok = 0;
        return 0.0;
    }
    return rnd(q);
}
static double f_from_int(int64_t n) { return rnd((double)n); }   /* |n| < 2**53 here */

/* ---- FirmwareState's slots -------------------------------------------------------- */

#define FIELDS(X) \
    X(lastControlTime) X(lastTickTime) X(lateTicks) X(txCredit) X(tickCount) \
    X(encTickL) X(encTickR) X(illTickL) X(illTickR) X(stormTickL) X(stormTickR) \
    X(rxLostTick) X(prevEncL) X(prevEncR) X(rawVelL) X(rawVelR) X(filtVelL) X(filtVelR) \
    X(faultFlags) X(stallTicksL) X(stallTicksR) X(reverseTicksL) X(reverseTicksR) \
    X(runawayTicksL) X(runawayTicksR) \
    X(effortPwmL) X(effortSpeedL) X(effortSetpointL) X(effortTicksL) \
    X(effortPwmR) X(effortSpeedR) X(effortSetpointR) X(effortTicksR) \
    X(pwmL) X(pwmR) X(dirL) X(dirR) X(setpointL) X(setpointR) X(targetL) X(targetR) \
    X(prevMeasL) X(prevMeasR) X(cmdSinceTick) X(lastCmdTime) X(watchdogArmed) \
    X(watchdogMs) X(feedbackForm) X(emergencyStop) X(estopDecel) X(maxAccel) X(stillTicks) X(parked) \
    X(integralL) X(integralR) X(outputL) X(outputR) X(kpL) X(kiL) X(kdL) X(kpR) X(kiR) \
    X(kdR) X(pivotPhase) X(pivotTicksLeft) X(pendingL) X(pendingR) X(mode) X(txDropped) \
    X(tlmEnabled) X(linesFramed) X(lineCounter) X(errLinesThisTick) X(rxCount) X(lastSeq) X(estopLatched) X(ppmLost) \
    X(rejectedCount) X(crcRejected) X(freeRam) \
    X(holding) X(holdRefL) X(holdRefR) X(holdStepL) X(holdStepR) \
    X(brakeReleased) X(overspeedTicksL) X(overspeedTicksR) X(overspeedFromL) X(overspeedFromR) \
    X(needNeutral) X(neutralFault) \
    X(inhibitTick) X(inhibitStable) X(inhibitCountL) X(inhibitCountR) X(inhibitLatched) X(inhibitPending) X(inhibitOn) X(inhibitCountP) \
    X(tremorDamping) X(dampedL) X(dampedR) \
    X(brakeFitted) X(profile) X(brakePhase) X(brakeTicks) X(brakeStatusTick) X(brakeStatusTicks) \
    X(windingTempL) X(windingTempR) X(thermalRollback) X(thermalPending) \
    X(supplyTick) X(supplyVolts) X(batteryLow) X(batteryPending) \
    X(currentTickL) X(currentTickR) X(stallTime) \
    X(fwdSpeed) X(revSpeed) X(driveAccel) X(driveDecel) X(turnSpeed) X(turnAccel) X(turnAtSpeed)

#define ENUM(name) F_##name,
enum { FIELDS(ENUM) N_FIELDS };
#define NAME(name) #name,
static const char *field_names[N_FIELDS] = { FIELDS(NAME) };

static PyTypeObject *state_type;
static Py_ssize_t offset[N_FIELDS];

static PyObject **slot(PyObject *s, int f) { return (PyObject **)((char *)s + offset[f]); }

/* What the tick reads (each field as a double or an int64, as field_is_float says) and
 * which fields it wrote. */
typedef struct {
    double d[N_FIELDS];
    int64_t i[N_FIELDS];
    unsigned char written[N_FIELDS];
} Vals;

#define INT_LIMIT ((int64_t)1 << 62)

static int read_int(PyObject *s, int f, Vals *v) {
    PyObject *o = *slot(s, f);
    if (o == NULL || !PyLong_CheckExact(o))
        return 0;
    int overflow = 0;
    long long n = PyLong_AsLongLongAndOverflow(o, &overflow);
    if (overflow || n >= INT_LIMIT || n <= -INT_LIMIT)
        return 0;
    v->i[f] = n;
    return 1;
}

static int read_float(PyObject *s, int f, Vals *v) {
    PyObject *o = *slot(s, f);
    if (o == NULL || !PyFloat_CheckExact(o))
        return 0;
    v->d[f] = PyFloat_AS_DOUBLE(o);
    return 1;
}

static int arg_int(PyObject *o, int64_t *out) {
    if (!PyLong_CheckExact(o))
        return 0;
    int overflow = 0;
    long long n = PyLong_AsLongLongAndOverflow(o, &overflow);
    if (overflow || n >= INT_LIMIT || n <= -INT_LIMIT)
        return 0;
    *out = n;
    return 1;
}

/* ---- constants (from _bind) ------------------------------------------------------- */

static struct {
    double alpha, one_minus_alpha, cpr, two_pi, pid_out_max, pwm_scale, still_speed,
        brake_done_speed, standing_speed, reverse_speed, reverse_approach, runaway_gain, effort_shortfall_motor, effort_lead, effort_overrun,
        overspeed_margin, overspeed_gain,
        pivot_start_speed,
        pivot_speed, rounding2, thermal_emf, effort_max, thermal_ambient, thermal_resistance,
        thermal_capacity, thermal_loss, thermal_rollback_temp, supply_volts_per_count, supply_filter,
        battery_low_v, drive_speed_max, drive_accel_max, turn_speed_max, turn_accel_max, turn_at_speed,
        drive_rate_max, wheel_radius, wheelbase, current_amps_per_count, stall_current, current_sense_max,
        motor_amps_per_duty, standing_draw_share, effort_shortfall, motor_draw_min;
    int64_t control_period_ms, tx_credit_max, tx_credit_per_ms, stall_pwm, stall_pwm_standing, stall_ticks,
        stall_ticks_turning, stall_ticks_loaded,
        reverse_ticks, runaway_pwm, runaway_ticks, effort_pwm, effort_ticks, illegal_per_tick, still_ticks, pivot_ticks,
        hold_deadband, overspeed_pwm, overspeed_ticks,
        high, low, pivot_none, pivot_stopping, pivot_rotating, untrusted_l, untrusted_r, brake_released,
        current_zero_counts, stall_creep_counts;
} K;
static PyObject *mode_names;      /* dict: mode -> bytes */
static int bound;

#define M32 0xFFFFFFFFLL
static int64_t i32(int64_t x) { return (int64_t)(int32_t)(uint32_t)(uint64_t)x; }

/* ---- text ------------------------------------------------------------------------- */

typedef struct { char b[512]; int n; } Buf;

static void put(Buf *o, const char *t, int n) {
    if (o->n + n <= (int)sizeof o->b) {
        memcpy(o->b + o->n, t, (size_t)n);
        o->n += n;
    } else {
        ok = 0;                     /* cannot happen for the lines below */
    }
}
static void puts_(Buf *o, const char *t) { put(o, t, (int)strlen(t)); }
static void put_ll(Buf *o, long long n) {
    char t[32];
    put(o, t, snprintf(t, sizeof t, "%lld", n));
}

/* Print::print(long) of a 32-bit value */
static void print_long(Buf *o, int64_t n) {
    if (n < 0) {
        puts_(o, "-");
        put_ll(o, (long long)((uint64_t)(-n) & M32));
    } else {
        put_ll(o, (long long)n);
    }
}

/* Print::printFloat(number, 2) (wcdrive.avr.arduino_print.print_float) */
static void print_float2(Buf *o, double number) {
    if (number != number) { puts_(o, "nan"); return; }
    if (isinf(number)) { puts_(o, "inf"); return; }
    if (number > 4294967040.0 || number < -4294967040.0) { puts_(o, "ovf"); return; }
    if (number < 0.0) {
        puts_(o, "-");
        number = -number;
    }
    number = rnd(number + K.rounding2);
    uint64_t int_part = (uint64_t)(int64_t)number & M32;
    double remainder = rnd(number - rnd((double)int_part));
    put_ll(o, (long long)int_part);
    puts_(o, ".");
    for (int k = 0; k < 2; k++) {
        remainder = f_mul(remainder, 10.0);
        int64_t to_print = (int64_t)remainder & 0xFFFF;
        put_ll(o, (long long)to_print);
        remainder = rnd(remainder - (double)to_print);
    }
}

/* ---- the tick's parts (the names of wcdrive.firmware.control) ---------------------- */

enum { WHEEL_OK, WHEEL_SUSPECT, WHEEL_FAULT };

typedef struct {
    int64_t pwm, ticks;
    double speed, setpoint;
} Effort;

/* no_effect: whether it tripped; *e the new reference */
static int no_effect(int64_t pwm, int64_t dir, double setpoint, double measured, double other,
                     int64_t other_pwm, int other_overruns, Effort *e) {
    double progress = setpoint > 0.0 ? measured : -measured;
    int toward = setpoint != 0.0 && ((dir == K.high) == (setpoint > 0.0));
    if (!toward || setpoint != e->setpoint || progress > e->speed || progress > fabs(setpoint)) {
        e->pwm = pwm;
        e->speed = progress;
        e->setpoint = setpoint;
        e->ticks = 0;
        return 0;
    }
    if (pwm < e->pwm)
        e->pwm = pwm;
    int shortfall = fabs(measured) < f_mul(K.effort_shortfall_motor, fabs(setpoint));
    double other_progress = setpoint > 0.0 ? other : -other;
    int trails = progress < f_add(other_progress > 0.0 ? other_progress : 0.0, K.effort_lead);
    e->ticks = (shortfall && trails && !other_overruns && (pwm >= e->pwm + K.effort_pwm
                                                        || (pwm == 255 && other_pwm + K.effort_pwm >= 255)))
                   ? ((e->ticks + 1) & 0xFF) : 0;
    return e->ticks >= K.effort_ticks;
}

/* overruns: driven toward its setpoint while EFFORT_OVERRUN beyond it */
static int overruns(int64_t pwm, int64_t dir, double setpoint, double measured) {
    double progress = setpoint > 0.0 ? measured : -measured;
    return setpoint != 0.0 && pwm > 0 && ((dir == K.high) == (setpoint > 0.0))
           && progress > f_add(fabs(setpoint), K.effort_overrun);
}

/* runs_away */
static int runs_away(int64_t pwm, int64_t dir, double setpoint, double measured,
                     double prev_measured) {
    int forward = measured > 0.0;
    double beyond = forward ? f_sub(measured, setpoint) : f_sub(setpoint, measured);
    return pwm >= K.runaway_pwm && ((dir == K.high) != forward)
           && fabs(measured) >= K.reverse_speed && beyond >= K.reverse_speed
           && f_sub(fabs(measured), fabs(prev_measured)) >= K.runaway_gain;
}

/* overspeeding: braked at OVERSPEED_PWM against its motion, OVERSPEED_MARGIN beyond its
 * setpoint */
static int overspeeding(int64_t pwm, int64_t dir, double setpoint, double target, double measured) {
    int forward = measured > 0.0;
    double beyond = forward ? f_sub(measured, setpoint) : f_sub(setpoint, measured);
    double beyond_target = forward ? f_sub(measured, target) : f_sub(target, measured);
    int along = setpoint == 0.0 || ((setpoint > 0.0) == forward);
    return along && pwm >= K.overspeed_pwm && ((dir == K.high) != forward)
           && beyond >= K.overspeed_margin && beyond_target >= K.overspeed_margin;
}

/* overspeedRun: counts the run in *ticks (wrapping at 256) from *from; whether it fires */
static int overspeed_run(int over, double measured, double prev_measured, int64_t *ticks, double *from) {
    if (!over) {
        *ticks = 0;
        return 0;
    }
    if (*ticks == 0)
        *from = fabs(prev_measured);
    *ticks = (*ticks + 1) & 0xFF;
    return *ticks >= K.overspeed_ticks && f_sub(fabs(measured), *from) >= K.overspeed_gain;
}

/* check_wheel: WHEEL_OK, WHEEL_SUSPECT or WHEEL_FAULT (any fault, and effort without
 * progress, which the other wheel may show to be the chair's load: the Python tick
 * decides and latches it) */
static int check_wheel(int64_t delta, int64_t illegal, int64_t storm, int64_t pwm, int64_t dir,
                       double setpoint, double measured, double other, int64_t other_pwm,
                       int other_overruns,
                       int64_t *stall, int64_t *reverse,
                       int64_t *runaway, Effort *e, double prev_measured, int holding, int loaded) {
    if (storm || illegal >= K.illegal_per_tick)
        return WHEEL_FAULT;
    double other_along = setpoint > 0.0 ? other : -other;
    int standing = fabs(prev_measured) < K.standing_speed && other_along < K.standing_speed;
    int64_t stall_pwm = standing ? K.stall_pwm_standing : K.stall_pwm;
    int driven = pwm >= stall_pwm && setpoint != 0.0 && ((dir == K.high) == (setpoint > 0.0));
    int stalled = driven && delta == 0;
    *stall = stalled ? ((*stall + 1) & 0xFF) : 0;
    int turning = prev_measured != 0.0 && ((prev_measured > 0.0) != (setpoint > 0.0));
    /* standing by its current on a loaded chair below full torque, it may stand a while */
    int64_t limit = loaded && pwm < K.stall_pwm_standing ? K.stall_ticks_loaded
                    : turning ? K.stall_ticks_turning : K.stall_ticks;
    if (*stall >= limit)
        return WHEEL_FAULT;
    double approach = setpoint > 0.0 ? f_sub(measured, prev_measured) : f_sub(prev_measured, measured);
    /* a wheel driven the way it reads agrees with its encoder */
    int drives_its_way = pwm > 0 && ((dir == K.high) == (measured > 0.0));
    int against = fabs(setpoint) >= K.reverse_speed && fabs(measured) >= K.reverse_speed
                  && (setpoint > 0.0) != (measured > 0.0) && approach < K.reverse_approach
                  && !drives_its_way;
    *reverse = against ? ((*reverse + 1) & 0xFF) : 0;
    if (*reverse >= K.reverse_ticks)
        return WHEEL_FAULT;
    if (runs_away(pwm, dir, setpoint, measured, prev_measured))
        *runaway = (*runaway + 1) & 0xFF;
    else
        *runaway = (*runaway > 0 && !holding) ? *runaway - 1 : 0;
    if (*runaway >= K.runaway_ticks)
        return WHEEL_FAULT;
    if (no_effect(pwm, dir, setpoint, measured, other, other_pwm, other_overruns, e))
        return WHEEL_FAULT;
    return (stalled || against) ? WHEEL_SUSPECT : WHEEL_OK;
}

/* stands_by_current: wcdrive.firmware.stall */
static int stands_by_current(int64_t pwm, int64_t dir, double setpoint, int64_t current,
                             double other_setpoint, double other) {
    if (setpoint == 0.0 || (dir == K.high) != (setpoint > 0.0))
        return 0;
    double other_progress = other_setpoint > 0.0 ? other : -other;
    if (other_progress >= f_mul(K.effort_shortfall, fabs(other_setpoint)))
        return 0;
    double amps = f_mul(f_from_int(current - K.current_zero_counts), K.current_amps_per_count);
    double drawn = dir == K.high ? amps : -amps;
    return drawn >= K.motor_draw_min
           && drawn >= f_mul(K.standing_draw_share, f_mul(f_from_int(pwm), K.motor_amps_per_duty));
}

/* winding_loss, winding_step: wcdrive.firmware.thermal */
static double winding_loss(int64_t pwm, int64_t dir, double vel) {
    double duty = dir == K.high ? (double)pwm : -(double)pwm;
    double effort = f_sub(duty, f_mul(K.thermal_emf, vel));
    if (effort > K.effort_max)
        effort = K.effort_max;
    else if (effort < -K.effort_max)
        effort = -K.effort_max;
    return f_mul(f_mul(effort, effort), K.thermal_loss);
}

static double winding_step(double temp, double loss, double dt) {
    double cool = f_div(f_sub(temp, K.thermal_ambient), K.thermal_resistance);
    return f_add(temp, f_div(f_mul(dt, f_sub(loss, cool)), K.thermal_capacity));
}

static double ramp_toward(double current, double target, double max_change) {
    double diff = f_sub(target, current);
    if (fabs(diff) <= max_change)
        return target;
    return f_add(current, diff > 0.0 ? max_change : -max_change);
}

/* compute_pid: the clamped output; *integral the new integral */
static double compute_pid(double setpoint, double measurement, double *integral, double prev_meas,
                          double kp, double ki, double kd, double dt) {
    double error = f_sub(setpoint, measurement);
    double in = f_add(*integral, f_mul(error, dt));
    double limit = f_div(K.pid_out_max, ki);
    in = in < -limit ? -limit : (in > limit ? limit : in);
    double derivative = f_div(-f_sub(measurement, prev_meas), dt);
    double p_term = f_mul(kp, error);
    double d_term = f_mul(kd, derivative);
    double output = f_add(f_add(p_term, f_mul(ki, in)), d_term);
    double m = K.pid_out_max;
    double clamped = output < -m ? -m : (output > m ? m : output);
    if (output != clamped) {
        in = f_div(f_sub(f_sub(clamped, p_term), d_term), ki);
        if ((in > 0.0) != (clamped > 0.0))
            in = 0.0;
    }
    *integral = in;
    return clamped;
}

static void set_motor(double output, int64_t *pwm, int64_t *dir) {
    *dir = output >= 0.0 ? K.high : K.low;
    double p = f_mul(fabs(output), K.pwm_scale);
    *pwm = (p != p || fabs(p) >= 2147483648.0) ? ((int64_t)INT32_MIN & 0xFF) : ((int64_t)p & 0xFF);
}

/* CRC-16/XMODEM, as avr-libc's _crc_xmodem_update */
static unsigned crc_xmodem(const char *b, int n) {
    unsigned crc = 0;
    for (int k = 0; k < n; k++) {
        crc ^= (unsigned)(unsigned char)b[k] << 8;
        for (int bit = 0; bit < 8; bit++)
            crc = (crc & 0x8000) ? ((crc << 1) ^ 0x1021) & 0xFFFF : (crc << 1) & 0xFFFF;
    }
    return crc;
}

/* send (LineBuffer::send): framed first after hello:4 ("<text>#NN*CCCC\r\n") */
static void send(Vals *v, Buf *out, const Buf *line) {
    Buf framed;
    if (v->i[F_linesFramed]) {
        int n = line->n - 2;
        memcpy(framed.b, line->b, (size_t)n);
        n += snprintf(framed.b + n, 4, "#%02X", (unsigned)(v->i[F_lineCounter] & 0xFF));
        unsigned crc = crc_xmodem(framed.b, n);
        n += snprintf(framed.b + n, 8, "*%04X\r\n", crc);
        framed.n = n;
        line = &framed;
    }
    if (line->n > v->i[F_txCredit]) {
        v->i[F_txDropped] = (v->i[F_txDropped] + 1) & M32;
    } else {
        v->i[F_txCredit] -= line->n;
        put(out, line->b, line->n);
        if (v->i[F_linesFramed]) {
            v->i[F_lineCounter] = (v->i[F_lineCounter] + 1) & 0xFF;
            v->written[F_lineCounter] = 1;
        }
    }
}

#define SETI(f, x) (v.i[F_##f] = (x), v.written[F_##f] = 1)
#define SETF(f, x) (v.d[F_##f] = (x), v.written[F_##f] = 1)
#define I(f) (v.i[F_##f])
#define D(f) (v.d[F_##f])

static const int float_fields[] = {
    F_rawVelL, F_rawVelR, F_filtVelL, F_filtVelR, F_effortSpeedL, F_effortSetpointL,
    F_effortSpeedR, F_effortSetpointR, F_setpointL, F_setpointR, F_targetL, F_targetR,
    F_prevMeasL, F_prevMeasR, F_estopDecel, F_maxAccel, F_integralL, F_integralR, F_outputL,
    F_outputR, F_kpL, F_kiL, F_kdL, F_kpR, F_kiR, F_kdR, F_pendingL, F_pendingR,
    F_overspeedFromL, F_overspeedFromR, F_windingTempL, F_windingTempR, F_supplyVolts,
    F_fwdSpeed, F_revSpeed, F_driveAccel, F_driveDecel, F_turnSpeed, F_turnAccel, F_turnAtSpeed, F_stallTime,
    F_tremorDamping, F_dampedL, F_dampedR,
};

static unsigned char field_is_float[N_FIELDS];     /* set by _bind from float_fields */

static PyObject *tick(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (!bound) {
        PyErr_SetString(PyExc_RuntimeError, "tick_fast: _bind() was not called");
        return NULL;
    }
    if (nargs != 13) {
        PyErr_SetString(PyExc_TypeError, "tick() takes 13 arguments");
        return NULL;
    }
    PyObject *s = args[0];
    if (Py_TYPE(s) != state_type)
        Py_RETURN_NONE;
    int64_t now, count_l, count_r, illegal_l, illegal_r, storm_l, storm_r, rx_lost, inhibit, supply;
    int64_t current_l, current_r;
    if (!arg_int(args[1], &now) || !arg_int(args[2], &count_l) || !arg_int(args[3], &count_r)
        || !arg_int(args[4], &illegal_l) || !arg_int(args[5], &illegal_r)
        || !arg_int(args[6], &storm_l) || !arg_int(args[7], &storm_r) || !arg_int(args[8], &rx_lost)
        || !arg_int(args[9], &inhibit) || !arg_int(args[10], &supply)
        || !arg_int(args[11], &current_l) || !arg_int(args[12], &current_r))
        Py_RETURN_NONE;

    Vals v;
    memset(v.written, 0, sizeof v.written);
    for (size_t k = 0; k < sizeof float_fields / sizeof float_fields[0]; k++)
        if (!read_float(s, float_fields[k], &v))
            Py_RETURN_NONE;
    for (int f = 0; f < N_FIELDS; f++) {
        if (field_is_float[f])
            continue;
        if (f == F_lastTickTime && *slot(s, f) == Py_None) {
            v.i[f] = -1;            /* None: lastControlTime, below */
            continue;
        }
        if (!read_int(s, f, &v))
            Py_RETURN_NONE;
    }
    if (I(needNeutral))
        Py_RETURN_NONE;             /* waiting for neutral (after a boot, a reset, a stop): the Python tick */
    if ((inhibit & 0xB) || I(inhibitTick) || I(inhibitStable) || I(inhibitCountL) || I(inhibitCountR)
        || I(inhibitCountP)
        || I(inhibitLatched) || I(inhibitPending) || I(inhibitOn))
        Py_RETURN_NONE;             /* an inhibit input read, engaged or settling: the Python tick */
    int brake_status = (int)((inhibit >> 2) & 1);
    if (I(brakeStatusTicks) || (I(brakeFitted) && (brake_status || I(brakePhase) != K.brake_released
                                                   || I(brakeTicks))))
        Py_RETURN_NONE;             /* a fitted brake not released and settled, or its status LOW */
    if (I(thermalRollback) || I(thermalPending))
        Py_RETURN_NONE;             /* the thermal rollback on, or its event to send */
    if (I(batteryLow) || I(batteryPending))
        Py_RETURN_NONE;             /* the low-battery rollback on, or its event to send */
    if (D(fwdSpeed) != K.drive_speed_max || D(revSpeed) != K.drive_speed_max
        || D(driveAccel) != K.drive_accel_max || D(driveDecel) != K.drive_accel_max
        || D(turnSpeed) != K.turn_speed_max || D(turnAccel) != K.turn_accel_max
        || D(turnAtSpeed) != K.turn_at_speed || D(tremorDamping) != 0.0)
        Py_RETURN_NONE;             /* a drive limit set (at the defaults none binds): the Python tick */
    {
        /* drive_caps and wheel_rate at the defaults: targets the wheels can take pass, and
         * a max_accel below the default ramp's rate is the ramp; anything else, Python */
        double speed = f_mul(f_mul(f_add(D(targetR), D(targetL)), 0.5), K.wheel_radius);
        double turn = f_div(f_mul(f_sub(D(targetR), D(targetL)), K.wheel_radius), K.wheelbase);
        if (!(speed <= K.drive_speed_max && speed >= -K.drive_speed_max && turn <= K.turn_speed_max
              && turn >= -K.turn_speed_max && D(maxAccel) < K.drive_rate_max))
            Py_RETURN_NONE;
    }
    SETI(brakeStatusTick, brake_status);
    PyObject *mode_name = PyDict_GetItemWithError(mode_names, *slot(s, F_mode));
    if (mode_name == NULL) {
        if (PyErr_Occurred())
            return NULL;
        Py_RETURN_NONE;
    }
    ok = 1;
    Buf out = { .n = 0 };

    int64_t last_tick = *slot(s, F_lastTickTime) == Py_None ? I(lastControlTime) : I(lastTickTime);
    int64_t elapsed = (now - last_tick) & M32;
    double dt = f_div(f_from_int(elapsed), 1000.0);
    SETI(lastTickTime, now & M32);
    if (((now - I(lastControlTime)) & M32) >= 2 * K.control_period_ms) {
        SETI(lastControlTime, now & M32);
        SETI(lateTicks, (I(lateTicks) + 1) & M32);
    } else {
        SETI(lastControlTime, (I(lastControlTime) + K.control_period_ms) & M32);
    }
    /* refill_credit */
    if (elapsed >= K.tx_credit_max / K.tx_credit_per_ms) {
        SETI(txCredit, K.tx_credit_max);
    } else {
        int64_t c = I(txCredit) + elapsed * K.tx_credit_per_ms;
        SETI(txCredit, c < K.tx_credit_max ? c : K.tx_credit_max);
    }
    SETI(tickCount, (I(tickCount) + 1) & M32);

    SETI(encTickL, i32(count_l));
    SETI(encTickR, i32(count_r));
    int64_t ill_l = (illegal_l - I(illTickL)) & M32;
    int64_t ill_r = (illegal_r - I(illTickR)) & M32;
    SETI(illTickL, illegal_l & M32);
    SETI(illTickR, illegal_r & M32);
    SETI(stormTickL, storm_l != 0);
    SETI(stormTickR, storm_r != 0);
    SETI(rxLostTick, rx_lost & M32);
    SETI(supplyTick, supply & 0x3FF);
    SETI(currentTickL, current_l & 0x3FF);
    SETI(currentTickR, current_r & 0x3FF);
    int64_t delta_l = i32(I(encTickL) - I(prevEncL));
    int64_t delta_r = i32(I(encTickR) - I(prevEncR));
    SETI(prevEncL, I(encTickL));
    SETI(prevEncR, I(encTickR));
    /* sense_amps: a wheel within STALL_CREEP_COUNTS whose motor is at STALL_CURRENT or
     * more (it may be held at its limit), or a failed sense, goes to the Python tick */
    double amps_l = fabs(f_mul(f_from_int(I(currentTickL) - K.current_zero_counts), K.current_amps_per_count));
    double amps_r = fabs(f_mul(f_from_int(I(currentTickR) - K.current_zero_counts), K.current_amps_per_count));
    int creeping_l = llabs(delta_l) <= K.stall_creep_counts && !(amps_l < K.stall_current);
    int creeping_r = llabs(delta_r) <= K.stall_creep_counts && !(amps_r < K.stall_current);
    if (creeping_l || creeping_r
        || !(amps_l <= K.current_sense_max) || !(amps_r <= K.current_sense_max))
        Py_RETURN_NONE;

    double per_second = f_div(K.two_pi, dt);
    SETF(rawVelL, f_mul(-f_div(f_from_int(delta_l), K.cpr), per_second));
    SETF(rawVelR, f_mul(f_div(f_from_int(delta_r), K.cpr), per_second));
    SETF(filtVelL, f_add(f_mul(K.alpha, D(rawVelL)), f_mul(K.one_minus_alpha, D(filtVelL))));
    SETF(filtVelR, f_add(f_mul(K.alpha, D(rawVelR)), f_mul(K.one_minus_alpha, D(filtVelR))));

    /* update_thermal: a winding past the rollback's start goes to the Python tick */
    SETF(windingTempL, winding_step(D(windingTempL), winding_loss(I(pwmL), I(dirL), D(filtVelL)), dt));
    SETF(windingTempR, winding_step(D(windingTempR), winding_loss(I(pwmR), I(dirR), D(filtVelR)), dt));
    if (D(windingTempL) > K.thermal_rollback_temp || D(windingTempR) > K.thermal_rollback_temp)
        Py_RETURN_NONE;
    /* update_supply: a supply below the low-battery threshold goes to the Python tick */
    double volts = f_mul(f_from_int(I(supplyTick)), K.supply_volts_per_count);
    SETF(supplyVolts, D(supplyVolts) == 0.0 ? volts
                      : f_add(D(supplyVolts), f_mul(K.supply_filter, f_sub(volts, D(supplyVolts)))));
    if (!(D(supplyVolts) >= K.battery_low_v))
        Py_RETURN_NONE;

    /* _check_faults: a fault that latches goes to the Python tick */
    int check_l = WHEEL_OK, check_r = WHEEL_OK;
    if (I(faultFlags) == 0) {
        int64_t stall_l = I(stallTicksL), rev_l = I(reverseTicksL), run_l = I(runawayTicksL);
        int64_t stall_r = I(stallTicksR), rev_r = I(reverseTicksR), run_r = I(runawayTicksR);
        Effort el = { I(effortPwmL), I(effortTicksL), D(effortSpeedL), D(effortSetpointL) };
        Effort er = { I(effortPwmR), I(effortTicksR), D(effortSpeedR), D(effortSetpointR) };
        int overrun_l = overruns(I(pwmL), I(dirL), D(setpointL), D(filtVelL));
        int overrun_r = overruns(I(pwmR), I(dirR), D(setpointR), D(filtVelR));
        check_l = check_wheel(delta_l, ill_l, I(stormTickL), I(pwmL), I(dirL), D(setpointL), D(filtVelL),
                              D(filtVelR), I(pwmR), overrun_r, &stall_l, &rev_l, &run_l, &el, D(prevMeasL),
                              (int)I(holding), stands_by_current(I(pwmL), I(dirL), D(setpointL), I(currentTickL),
                                                D(setpointR), D(filtVelR)));
        check_r = check_wheel(delta_r, ill_r, I(stormTickR), I(pwmR), I(dirR), D(setpointR), D(filtVelR),
                              D(filtVelL), I(pwmL), overrun_l, &stall_r, &rev_r, &run_r, &er, D(prevMeasR),
                              (int)I(holding), stands_by_current(I(pwmR), I(dirR), D(setpointR), I(currentTickR),
                                                D(setpointL), D(filtVelL)));
        if (check_l == WHEEL_FAULT || check_r == WHEEL_FAULT)
            Py_RETURN_NONE;
        SETI(stallTicksL, stall_l); SETI(reverseTicksL, rev_l);
        SETI(stallTicksR, stall_r); SETI(reverseTicksR, rev_r);
        SETI(runawayTicksL, run_l); SETI(runawayTicksR, run_r);
        SETF(stallTime, 0.0);     /* no wheel held at its current limit (above) */
        SETI(effortPwmL, el.pwm); SETF(effortSpeedL, el.speed);
        SETF(effortSetpointL, el.setpoint); SETI(effortTicksL, el.ticks);
        SETI(effortPwmR, er.pwm); SETF(effortSpeedR, er.speed);
        SETF(effortSetpointR, er.setpoint); SETI(effortTicksR, er.ticks);
        int64_t os_l = I(overspeedTicksL), os_r = I(overspeedTicksR);
        double from_l = D(overspeedFromL), from_r = D(overspeedFromR);
        int fire_l = overspeed_run(!I(holding) && overspeeding(I(pwmL), I(dirL), D(setpointL), D(targetL),
                                                               D(filtVelL)),
                                   D(filtVelL), D(prevMeasL), &os_l, &from_l);
        int fire_r = overspeed_run(!I(holding) && overspeeding(I(pwmR), I(dirR), D(setpointR), D(targetR),
                                                               D(filtVelR)),
                                   D(filtVelR), D(prevMeasR), &os_r, &from_r);
        if (fire_l || fire_r)
            Py_RETURN_NONE;       /* an overspeed parks the chair, one wheel's is its motor's fault: the Python tick */
        SETI(overspeedTicksL, os_l); SETI(overspeedTicksR, os_r);
        SETF(overspeedFromL, from_l); SETF(overspeedFromR, from_r);
    }

    if (I(cmdSinceTick)) {
        SETI(cmdSinceTick, 0);
        SETI(lastCmdTime, now & M32);
        SETI(watchdogArmed, 1);
    }
    if (I(watchdogArmed) && ((now - I(lastCmdTime)) & M32) >= I(watchdogMs))
        Py_RETURN_NONE;           /* the watchdog fires: the Python tick */

    /* damped_targets without damping (tremor_damping 0, above): the targets */
    SETF(dampedL, D(targetL));
    SETF(dampedR, D(targetR));
    double max_change = f_mul(I(emergencyStop) ? D(estopDecel) : D(maxAccel), dt);
    SETF(setpointL, ramp_toward(D(setpointL), D(targetL), max_change));
    SETF(setpointR, ramp_toward(D(setpointR), D(targetR), max_change));
    /* stopped, no pivot: an integral driving a wheel the way it still turns is dropped */
    if (I(pivotPhase) == K.pivot_none) {
        if (D(targetL) == 0.0 && D(setpointL) == 0.0 && D(integralL) != 0.0
            && ((D(integralL) > 0.0) == (D(filtVelL) > 0.0)))
            SETF(integralL, 0.0);
        if (D(targetR) == 0.0 && D(setpointR) == 0.0 && D(integralR) != 0.0
            && ((D(integralR) > 0.0) == (D(filtVelR) > 0.0)))
            SETF(integralR, 0.0);
    }

    int still = fabs(D(filtVelL)) < K.still_speed && fabs(D(filtVelR)) < K.still_speed;
    if (!still)
        SETI(stillTicks, 0);
    else if (I(stillTicks) < 255)
        SETI(stillTicks, I(stillTicks) + 1);
    int at_rest = D(targetL) == 0.0 && D(targetR) == 0.0 && D(setpointL) == 0.0 && D(setpointR) == 0.0;
    int trusted_l = !(I(faultFlags) & K.untrusted_l), trusted_r = !(I(faultFlags) & K.untrusted_r);
    int braked = (!trusted_l || fabs(D(filtVelL)) < K.brake_done_speed)
                 && (!trusted_r || fabs(D(filtVelR)) < K.brake_done_speed);
    int park = (!trusted_l && !trusted_r)
               || (at_rest && (I(holding) || braked));
    /* The hold: only its quiet case here, each held wheel within the deadband of a fixed
     * reference (duty 0; a faulty wheel mirrors it). Its start and end, a reference that still
     * follows its wheel, a duty or a rollaway go to the Python tick. */
    int held_l = park && trusted_l, held_r = park && trusted_r;
    int hold = held_l || held_r;
    if (hold != (I(holding) != 0) || (I(brakeFitted) && park))
        Py_RETURN_NONE;
    if (held_l) {
        if (I(holdStepL) != 0 || llabs(i32(I(encTickL) - I(holdRefL))) > K.hold_deadband)
            Py_RETURN_NONE;
        SETI(holdRefL, I(holdRefL)); SETI(holdStepL, 0);
    }
    if (held_r) {
        if (I(holdStepR) != 0 || llabs(i32(I(encTickR) - I(holdRefR))) > K.hold_deadband)
            Py_RETURN_NONE;
        SETI(holdRefR, I(holdRefR)); SETI(holdStepR, 0);
    }
    SETI(holding, hold);
    SETI(brakeReleased, park || I(faultFlags) ? 0 : 1);
    if (park) {
        SETI(parked, 1);
        SETF(integralL, 0.0);
        SETF(integralR, 0.0);
        SETF(prevMeasL, D(filtVelL));
        SETF(prevMeasR, D(filtVelR));
        SETF(outputL, 0.0);
        SETF(outputR, 0.0);
    } else {
        SETI(parked, 0);
        if (trusted_l && check_l != WHEEL_SUSPECT) {
            double in = D(integralL);
            SETF(outputL, compute_pid(D(setpointL), D(filtVelL), &in, D(prevMeasL), D(kpL), D(kiL),
                                      D(kdL), dt));
            SETF(integralL, in);
            SETF(prevMeasL, D(filtVelL));
        }
        if (trusted_r && check_r != WHEEL_SUSPECT) {
            double in = D(integralR);
            SETF(outputR, compute_pid(D(setpointR), D(filtVelR), &in, D(prevMeasR), D(kpR), D(kiR),
                                      D(kdR), dt));
            SETF(integralR, in);
            SETF(prevMeasR, D(filtVelR));
        }
        /* after a fault the faulty wheel at duty 0: the driver brakes it whichever way it turns */
        if (!trusted_l)
            SETF(outputL, 0.0);
        if (!trusted_r)
            SETF(outputR, 0.0);
    }
    int64_t pwm, dir;
    set_motor(D(outputL), &pwm, &dir);
    SETI(pwmL, pwm); SETI(dirL, dir);
    set_motor(D(outputR), &pwm, &dir);
    SETI(pwmR, pwm); SETI(dirR, dir);

    /* pivot_step */
    int slow = fabs(D(filtVelL)) < K.pivot_start_speed && fabs(D(filtVelR)) < K.pivot_start_speed;
    if (I(pivotPhase) == K.pivot_stopping && D(setpointL) == 0.0 && D(setpointR) == 0.0 && slow) {
        SETI(pivotPhase, K.pivot_rotating);
        SETI(pivotTicksLeft, K.pivot_ticks);
        SETF(targetR, K.pivot_speed);
        SETF(targetL, -K.pivot_speed);
    } else if (I(pivotPhase) == K.pivot_rotating) {
        SETI(pivotTicksLeft, I(pivotTicksLeft) - 1);
        if (I(pivotTicksLeft) == 0) {
            SETI(pivotPhase, K.pivot_none);
            SETF(targetL, D(pendingL));
            SETF(targetR, D(pendingR));
        }
    }

    /* feedback_line, then TLM */
    Buf line = { .n = 0 };
    puts_(&line, "ENC:");
    print_long(&line, I(encTickL));
    puts_(&line, ",");
    print_long(&line, I(encTickR));
    puts_(&line, ",VEL:");
    print_float2(&line, D(rawVelL));
    puts_(&line, ",");
    print_float2(&line, D(rawVelR));
    puts_(&line, ",MODE:");
    put(&line, PyBytes_AS_STRING(mode_name), (int)PyBytes_GET_SIZE(mode_name));
    if (I(feedbackForm) && !I(linesFramed)) {   /* wheel_tail */
        puts_(&line, D(rawVelR) < 0.0 ? ",rn" : ",rp");
        print_float2(&line, fabs(D(rawVelR)));
        puts_(&line, D(rawVelL) < 0.0 ? ",ln" : ",lp");
        print_float2(&line, fabs(D(rawVelL)));
    }
    puts_(&line, "\r\n");
    send(&v, &out, &line);
    v.written[F_txCredit] = v.written[F_txDropped] = 1;
    if (I(tlmEnabled)) {
        int64_t flags = (I(watchdogArmed) ? 1 : 0) | (I(emergencyStop) ? 2 : 0)
                        | (I(estopLatched) ? 4 : 0) | (I(ppmLost) ? 8 : 0) | (I(parked) ? 16 : 0)
                        | (int64_t)(((uint64_t)I(pivotPhase) << 5) & 0xFF) | (I(faultFlags) ? 128 : 0);
        int64_t tlm[18] = { now & M32, I(rxCount), I(lastSeq), I(pwmL), I(pwmR), I(dirL), I(dirR),
                            I(illTickL), I(illTickR), flags, I(rejectedCount), I(crcRejected),
                            I(freeRam), I(faultFlags), I(rxLostTick), I(lateTicks),
                            (I(needNeutral) ? 1 : 0) | (I(neutralFault) ? 2 : 0)
                            | (I(brakeFitted) && !I(brakeReleased) ? 16 : 0) | (I(profile) << 8),
                            /* the supply, tenths of a volt: positive and small here */
                            (int64_t)f_add(f_mul(D(supplyVolts), 10.0), 0.5) };
        Buf t = { .n = 0 };
        puts_(&t, "TLM:");
        for (int k = 0; k < 18; k++) {
            if (k)
                puts_(&t, ",");
            put_ll(&t, (long long)tlm[k]);
        }
        puts_(&t, "\r\n");
        send(&v, &out, &t);
    }
    SETI(errLinesThisTick, 0);
    if (!ok)
        Py_RETURN_NONE;

    /* commit: every new value made first, then swapped in */
    PyObject *made[N_FIELDS];
    int n_made = 0, which[N_FIELDS];
    for (int f = 0; f < N_FIELDS; f++) {
        if (!v.written[f])
            continue;
        PyObject *o = field_is_float[f] ? PyFloat_FromDouble(v.d[f]) : PyLong_FromLongLong(v.i[f]);
        if (o == NULL) {
            for (int k = 0; k < n_made; k++)
                Py_DECREF(made[k]);
            return NULL;
        }
        made[n_made] = o;
        which[n_made++] = f;
    }
    PyObject *result = PyBytes_FromStringAndSize(out.b, out.n);
    if (result == NULL) {
        for (int k = 0; k < n_made; k++)
            Py_DECREF(made[k]);
        return NULL;
    }
    for (int k = 0; k < n_made; k++) {
        PyObject **p = slot(s, which[k]);
        PyObject *old = *p;
        *p = made[k];
        Py_XDECREF(old);
    }
    return result;
}

/* ---- binding ---------------------------------------------------------------------- */

static int const_double(PyObject *d, const char *name, double *out) {
    PyObject *o = PyDict_GetItemString(d, name);
    if (o == NULL || !PyFloat_CheckExact(o)) {
        PyErr_Format(PyExc_ValueError, "_bind: constant %s must be a float", name);
        return 0;
    }
    *out = PyFloat_AS_DOUBLE(o);
    return 1;
}

static int const_int(PyObject *d, const char *name, int64_t *out) {
    PyObject *o = PyDict_GetItemString(d, name);
    if (o == NULL || !PyLong_CheckExact(o)) {
        PyErr_Format(PyExc_ValueError, "_bind: constant %s must be an int", name);
        return 0;
    }
    *out = PyLong_AsLongLong(o);
    return !PyErr_Occurred();
}

static PyObject *bind(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *type, *consts, *names;
    if (!PyArg_ParseTuple(args, "O!O!O!:_bind", &PyType_Type, &type, &PyDict_Type, &consts,
                          &PyDict_Type, &names))
        return NULL;
    Py_ssize_t offs[N_FIELDS];
    for (int f = 0; f < N_FIELDS; f++) {
        PyObject *descr = PyDict_GetItemString(((PyTypeObject *)type)->tp_dict, field_names[f]);
        if (descr == NULL || !Py_IS_TYPE(descr, &PyMemberDescr_Type)
            || ((PyMemberDescrObject *)descr)->d_member->type != T_OBJECT_EX) {
            PyErr_Format(PyExc_TypeError, "_bind: %s is not a slot of the state type", field_names[f]);
            return NULL;
        }
        offs[f] = ((PyMemberDescrObject *)descr)->d_member->offset;
    }
    PyObject *key, *value;
    Py_ssize_t pos = 0;
    while (PyDict_Next(names, &pos, &key, &value)) {
        if (!PyBytes_CheckExact(value) || PyBytes_GET_SIZE(value) > 32) {
            PyErr_SetString(PyExc_TypeError, "_bind: mode names must be short bytes");
            return NULL;
        }
    }
    typeof(K) k;
    if (!(const_double(consts, "ALPHA", &k.alpha) && const_double(consts, "ONE_MINUS_ALPHA", &k.one_minus_alpha)
          && const_double(consts, "CPR", &k.cpr) && const_double(consts, "TWO_PI", &k.two_pi)
          && const_double(consts, "PID_OUT_MAX", &k.pid_out_max) && const_double(consts, "PWM_SCALE", &k.pwm_scale)
          && const_double(consts, "STILL_SPEED", &k.still_speed)
          && const_double(consts, "BRAKE_DONE_SPEED", &k.brake_done_speed)
          && const_double(consts, "FAULT_REVERSE_SPEED", &k.reverse_speed)
          && const_double(consts, "FAULT_STANDING_SPEED", &k.standing_speed)
          && const_double(consts, "FAULT_REVERSE_APPROACH", &k.reverse_approach)
          && const_double(consts, "FAULT_RUNAWAY_GAIN", &k.runaway_gain)
          && const_double(consts, "FAULT_EFFORT_SHORTFALL_MOTOR", &k.effort_shortfall_motor)
          && const_double(consts, "FAULT_EFFORT_LEAD", &k.effort_lead)
          && const_double(consts, "FAULT_EFFORT_OVERRUN", &k.effort_overrun)
          && const_double(consts, "PIVOT_START_SPEED", &k.pivot_start_speed)
          && const_double(consts, "PIVOT_SPEED", &k.pivot_speed)
          && const_double(consts, "ROUNDING_2", &k.rounding2)
          && const_double(consts, "THERMAL_EMF", &k.thermal_emf)
          && const_double(consts, "FAULT_EFFORT_MAX", &k.effort_max)
          && const_double(consts, "THERMAL_AMBIENT", &k.thermal_ambient)
          && const_double(consts, "THERMAL_RESISTANCE", &k.thermal_resistance)
          && const_double(consts, "THERMAL_CAPACITY", &k.thermal_capacity)
          && const_double(consts, "THERMAL_LOSS", &k.thermal_loss)
          && const_double(consts, "THERMAL_ROLLBACK_TEMP", &k.thermal_rollback_temp)
          && const_double(consts, "SUPPLY_VOLTS_PER_COUNT", &k.supply_volts_per_count)
          && const_double(consts, "SUPPLY_FILTER", &k.supply_filter)
          && const_double(consts, "BATTERY_LOW_V", &k.battery_low_v)
          && const_double(consts, "DRIVE_SPEED_MAX", &k.drive_speed_max)
          && const_double(consts, "DRIVE_ACCEL_MAX", &k.drive_accel_max)
          && const_double(consts, "TURN_SPEED_MAX", &k.turn_speed_max)
          && const_double(consts, "TURN_ACCEL_MAX", &k.turn_accel_max)
          && const_double(consts, "TURN_AT_SPEED", &k.turn_at_speed)
          && const_double(consts, "DRIVE_RATE_MAX", &k.drive_rate_max)
          && const_double(consts, "WHEEL_RADIUS", &k.wheel_radius)
          && const_double(consts, "WHEELBASE", &k.wheelbase)
          && const_double(consts, "CURRENT_AMPS_PER_COUNT", &k.current_amps_per_count)
          && const_double(consts, "STALL_CURRENT", &k.stall_current)
          && const_double(consts, "CURRENT_SENSE_MAX", &k.current_sense_max)
          && const_double(consts, "MOTOR_AMPS_PER_DUTY", &k.motor_amps_per_duty)
          && const_double(consts, "STANDING_DRAW_SHARE", &k.standing_draw_share)
          && const_double(consts, "FAULT_EFFORT_SHORTFALL", &k.effort_shortfall)
          && const_double(consts, "MOTOR_DRAW_MIN", &k.motor_draw_min)
          && const_int(consts, "CURRENT_ZERO_COUNTS", &k.current_zero_counts)
          && const_int(consts, "STALL_CREEP_COUNTS", &k.stall_creep_counts)
          && const_int(consts, "CONTROL_PERIOD_MS", &k.control_period_ms)
          && const_int(consts, "TX_CREDIT_MAX", &k.tx_credit_max)
          && const_int(consts, "TX_CREDIT_PER_MS", &k.tx_credit_per_ms)
          && const_int(consts, "FAULT_STALL_PWM", &k.stall_pwm)
          && const_int(consts, "FAULT_STALL_PWM_STANDING", &k.stall_pwm_standing)
          && const_int(consts, "FAULT_STALL_TICKS", &k.stall_ticks)
          && const_int(consts, "FAULT_STALL_TICKS_TURNING", &k.stall_ticks_turning)
          && const_int(consts, "FAULT_STALL_TICKS_LOADED", &k.stall_ticks_loaded)
          && const_int(consts, "FAULT_REVERSE_TICKS", &k.reverse_ticks)
          && const_int(consts, "FAULT_RUNAWAY_PWM", &k.runaway_pwm)
          && const_int(consts, "FAULT_RUNAWAY_TICKS", &k.runaway_ticks)
          && const_int(consts, "FAULT_EFFORT_PWM", &k.effort_pwm)
          && const_int(consts, "FAULT_EFFORT_TICKS", &k.effort_ticks)
          && const_int(consts, "FAULT_ILLEGAL_PER_TICK", &k.illegal_per_tick)
          && const_int(consts, "STILL_TICKS", &k.still_ticks)
          && const_int(consts, "HOLD_DEADBAND_COUNTS", &k.hold_deadband)
          && const_double(consts, "OVERSPEED_MARGIN", &k.overspeed_margin)
          && const_double(consts, "OVERSPEED_GAIN", &k.overspeed_gain)
          && const_int(consts, "OVERSPEED_PWM", &k.overspeed_pwm)
          && const_int(consts, "OVERSPEED_TICKS", &k.overspeed_ticks)
          && const_int(consts, "PIVOT_TICKS", &k.pivot_ticks)
          && const_int(consts, "HIGH", &k.high) && const_int(consts, "LOW", &k.low)
          && const_int(consts, "PIVOT_NONE", &k.pivot_none)
          && const_int(consts, "PIVOT_STOPPING", &k.pivot_stopping)
          && const_int(consts, "PIVOT_ROTATING", &k.pivot_rotating)
          && const_int(consts, "FAULTS_UNTRUSTED_L", &k.untrusted_l)
          && const_int(consts, "FAULTS_UNTRUSTED_R", &k.untrusted_r)
          && const_int(consts, "BRAKE_RELEASED", &k.brake_released)))
        return NULL;
    if (k.tx_credit_per_ms <= 0) {
        PyErr_SetString(PyExc_ValueError, "_bind: TX_CREDIT_PER_MS must be positive");
        return NULL;
    }
    K = k;
    memcpy(offset, offs, sizeof offset);
    memset(field_is_float, 0, sizeof field_is_float);
    for (size_t k = 0; k < sizeof float_fields / sizeof float_fields[0]; k++)
        field_is_float[float_fields[k]] = 1;
    Py_INCREF(type);
    Py_XSETREF(state_type, (PyTypeObject *)type);
    Py_INCREF(names);
    Py_XSETREF(mode_names, names);
    bound = 1;
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"tick", (PyCFunction)(void (*)(void))tick, METH_FASTCALL,
     "tick(state, now, count_l, count_r, illegal_l, illegal_r, storm_l, storm_r, rx_lost): "
     "control_tick's bytes, or None (nothing changed: the Python tick runs)."},
    {"_bind", bind, METH_VARARGS, "_bind(FirmwareState, constants, mode names)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_tick_fast",
    "The common case of the port's control tick in C (see tick_fast.c).", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__tick_fast(void) {
    return PyModule_Create(&module);
}
