/*
 * chair_kernel: the inner loop of wcdrive.plant.Plant in C, for speed.
 *
 * chair_advance() runs n physics steps: the same force model as Plant._python_step
 * (wcdrive/plant/force_model.py, the reference; tests/plant/test_plant.py checks the two agree),
 * then Chipmunk's cpSpaceStep through function pointers that pymunk's own library
 * provides, so pymunk still integrates the chassis (and any walls in its space).
 *
 * When the chassis is alone in its space (lone_body(): the one body, no constraints, no
 * shape on it, sleeping off, pymunk's default update functions), cpSpaceStep has nothing
 * to do but what it does for each body: cpBodyUpdatePosition, then
 * cpBodyUpdateVelocity with the space's gravity and cpfpow(damping, dt). Those two
 * Chipmunk functions are called directly then (space_step()): the same code on the same
 * numbers, without the collision and solver passes (about 30% of a step). Two things
 * cpSpaceStep also does are skipped, as nothing of the plant reads them: the space's
 * time stamp and its current step (pymunk's Space.current_time_step stays as it was).
 * tests/plant/test_plant.py holds the two paths to the same motion bit for bit.
 * The floor's grade (force_model.grade) runs only when the plant has a terrain that is not
 * flat, so the flat floor's steps are the same operations as without one.
 * Built at install (setup.py's NATIVE) or else on first use by wcdrive._util.native
 * (gcc -O2 -ffp-contract=off).
 */
#include <math.h>
#include <stddef.h>
#include <stdint.h>

#define SWIVEL_RATE_SCALE 0.2   /* rad/s, as in force_model.py */
#define SCRUB_SLIP 1e-4         /* m/s, as in force_model.py */
#define MAX_RAMPS 8             /* wcdrive.plant.terrain.MAX_RAMPS */
#define BRAKE_SLACK 1e-9        /* s, as in force_model.py */

typedef struct { double x, y; } vec_t;
typedef vec_t (*get_vec_fn)(const void *);
typedef double (*get_f_fn)(const void *);
typedef void (*set_vec_fn)(void *, vec_t);
typedef void (*set_f_fn)(void *, double);
typedef void (*step_fn)(void *, double);
typedef void (*update_velocity_fn)(void *, vec_t, double, double);
typedef void (*each_fn)(void *, void *, void *);
typedef int (*get_type_fn)(const void *);

typedef struct {
    /* parameters */
    double half_base, r, cog_x, caster_x, caster_y, trail, swivel_max, swivel_friction;
    double mu[2], mu_c, n_drive, n_caster, crr, crr_c, c_long, c_lat, c_caster;
    double j, b, k1, k2, ke_g, tau_max, i_max_r, res;
    /* chipmunk */
    void *space, *body;
    void *get_velocity, *get_angle, *get_angular_velocity, *set_force, *set_torque, *space_step;
    void *update_position, *update_velocity, *get_damping, *get_gravity, *get_sleep_threshold;
    void *each_body, *each_constraint, *body_each_shape, *get_body_type;
    /* state */
    double volts[2];
    double angle[2], speed[2], current[2], slip[2], force[2];
    double caster_heading[2];
    double scrub_energy, scrub_time, swivel_work, side_impulse, time;
    /* faults (Plant.set_wheel_locked, Plant.set_motor_dead) */
    int32_t locked[2], dead[2];
    /* the body has update functions of its own (pymunk's velocity_func/position_func) */
    int32_t custom_funcs;
    /* the floor (force_model.set_terrain): off on the flat; a uniform grade (sin, cos) and
     * bands along the downhill heading (down_c, down_s) with their own */
    int32_t terrain, n_ramps;
    double mass_g, cog_h, n_drive0, n_caster0, down_c, down_s, slope_sin, slope_cos;
    double ramp_from[MAX_RAMPS], ramp_to[MAX_RAMPS], ramp_sin[MAX_RAMPS], ramp_cos[MAX_RAMPS];
    void *get_position;
    /* the drive tyres' patches as springs (force_model.wheel, deflect): stiffness along and
     * sideways, their inverses (0 for no spring), each wheel's deflections */
    double k_long, k_lat, inv_k_long, inv_k_lat;
    double defl[2], defl_lat[2];
    /* the parking brake (Plant.set_brake): its torque, what is left of its delay, whether
     * the chair has one, the pin (1 high: release) and the brake's state */
    double brake_torque, brake_wait;
    /* the motors' windings as one thermal mass each (force_model.heat): thermal
     * resistance to ambient (K/W), heat capacity (J/K; 0: no model), ambient (deg C), and
     * each winding's temperature */
    double th_res, th_cap, t_amb;
    double temp[2];
    /* the battery (force_model.battery): its open-circuit voltage empty and full, internal
     * resistance, charge in coulombs (0: no model, the motors see volts as set), state of
     * charge (0..1), terminal voltage over the last step, and each motor's signed duty */
    double bat_e0, bat_e1, bat_r, bat_cap, soc, bat_v;
    double duty[2];
    int32_t has_brake, brake_pin, brake_engaged;
} chair_t;

typedef struct { int n; void *last; } count_t;
static void count_one(void *item, void *data) { ((count_t *)data)->n++; ((count_t *)data)->last = item; }
static void count_shape(void *body, void *shape, void *data) { (void)body; (void)shape; ++*(int *)data; }

#define CP_BODY_TYPE_DYNAMIC 0

/* Whether cpSpaceStep would do nothing for this space but integrate the chassis: the
 * chassis, dynamic, is the space's one body. */
static int lone_body(const chair_t *c) {
    count_t bodies = { 0, NULL };
    if (c->custom_funcs || !isinf(((get_f_fn)c->get_sleep_threshold)(c->space))
        || ((get_type_fn)c->get_body_type)(c->body) != CP_BODY_TYPE_DYNAMIC)
        return 0;
    ((each_fn)c->each_body)(c->space, (void *)count_one, &bodies);
    if (bodies.n != 1 || bodies.last != c->body)
        return 0;
    count_t constraints = { 0, NULL };
    ((each_fn)c->each_constraint)(c->space, (void *)count_one, &constraints);
    if (constraints.n != 0)
        return 0;
    int n = 0;
    ((each_fn)c->body_each_shape)(c->body, (void *)count_shape, &n);
    return n == 0;
}

/* cpSpaceStep(space, dt), or for a lone body what it does for that body. */
static void space_step(chair_t *c, int lone, double dt) {
    if (!lone) {
        ((step_fn)c->space_step)(c->space, dt);
        return;
    }
    if (dt == 0.0)
        return;
    ((set_f_fn)c->update_position)(c->body, dt);
    double damping = pow(((get_f_fn)c->get_damping)(c->space), dt);
    vec_t gravity = ((get_vec_fn)c->get_gravity)(c->space);
    ((update_velocity_fn)c->update_velocity)(c->body, gravity, damping, dt);
}

static double clampd(double v, double lo, double hi) { return v > hi ? hi : (v < lo ? lo : v); }

/* force_model.deflect: the patch's deflection after a step at this slip, within most */
static double deflect(double z, double slip, double most, double dt) { return clampd(z + slip * dt, -most, most); }

/* force_model.stand_still: the wheel stands still over the step (locked, or held by the
 * brake), its patch holding or sliding with force; a stalled motor (no current when dead) */
static double stand_still(chair_t *c, int i, double force, double ground, double fmax, double dt) {
    double imax = c->i_max_r / c->res;
    c->speed[i] = 0.0;
    c->current[i] = c->dead[i] ? 0.0 : clampd(c->volts[i] / c->res, -imax, imax);
    c->slip[i] = -ground;
    c->force[i] = force;
    c->defl[i] = deflect(c->defl[i], -ground, fmax * c->inv_k_long, dt);
    return force;
}

static double wheel(chair_t *c, int i, double ground, double dt) {
    double r = c->r, cd = c->c_long, j_dt = c->j / dt, b = c->b;
    double k = c->k_long;
    double ce = cd + k * dt;
    double f0 = k * c->defl[i];
    double volts = c->volts[i], speed = c->speed[i];
    double fmax = c->mu[i] * c->n_drive;
    if (c->locked[i])
        return stand_still(c, i, clampd(f0 + ce * -ground, -fmax, fmax), ground, fmax, dt);
    double tb = 0.0;
    if (c->brake_engaged) {
        /* what holding the wheel still takes (force_model.wheel) */
        double hold = clampd(f0 + ce * -ground, -fmax, fmax);
        double stall = c->dead[i] ? 0.0 : clampd(c->k1 * volts, -c->tau_max, c->tau_max);
        tb = r * hold - j_dt * speed - stall;
        if (fabs(tb) <= c->brake_torque)
            return stand_still(c, i, hold, ground, fmax, dt);
        tb = copysign(c->brake_torque, tb);
    }
    double rr = c->crr * c->n_drive * tanh(ground / 0.01);
    if (c->dead[i]) {
        /* open circuit: no torque, no current, so no back-EMF term either */
        double w = (j_dt * speed + r * ce * ground - r * f0 + tb) / (j_dt + b + r * r * ce);
        double force = f0 + ce * (r * w - ground);
        if (fabs(force) > fmax) {
            force = copysign(fmax, force);
            w = (j_dt * speed - r * force + tb) / (j_dt + b);
        }
        c->speed[i] = w;
        c->angle[i] += w * dt;
        c->current[i] = 0.0;
        c->slip[i] = r * w - ground;
        c->force[i] = force;
        c->defl[i] = deflect(c->defl[i], c->slip[i], fmax * c->inv_k_long, dt);
        return force - rr;
    }
    double k1v = c->k1 * volts, tau = 0.0;
    double w = (j_dt * speed + k1v + r * ce * ground - r * f0 + tb) / (j_dt + c->k2 + b + r * r * ce);
    int limited = fabs(volts - c->ke_g * w) > c->i_max_r;
    if (limited) {
        tau = copysign(c->tau_max, volts - c->ke_g * w);
        w = (j_dt * speed + tau + r * ce * ground - r * f0 + tb) / (j_dt + b + r * r * ce);
    }
    double force = f0 + ce * (r * w - ground);
    if (fabs(force) > fmax) {
        /* the patch slides: speed and current limit solved again (force_model.wheel) */
        force = copysign(fmax, force);
        w = (j_dt * speed + k1v - r * force + tb) / (j_dt + c->k2 + b);
        limited = fabs(volts - c->ke_g * w) > c->i_max_r;
        if (limited) {
            tau = copysign(c->tau_max, volts - c->ke_g * w);
            w = (j_dt * speed + tau - r * force + tb) / (j_dt + b);
        }
    }
    c->speed[i] = w;
    c->angle[i] += w * dt;
    c->current[i] = (volts - c->ke_g * w) / c->res;
    if (limited || fabs(c->current[i]) * c->res > c->i_max_r)
        c->current[i] = copysign(c->i_max_r / c->res, volts - c->ke_g * w);
    c->slip[i] = r * w - ground;
    c->force[i] = force;
    c->defl[i] = deflect(c->defl[i], c->slip[i], fmax * c->inv_k_long, dt);
    return force - rr;
}

/* force_model.grade: the normal loads on the floor under (x, y), the chassis heading
 * (cs, sn); the grade's pull on the chassis (world frame) into *gx, *gy. */
static void grade(chair_t *c, double x, double y, double cs, double sn, double *gx, double *gy) {
    double along = x * c->down_c + y * c->down_s;
    double g_sin = c->slope_sin, g_cos = c->slope_cos;
    for (int i = 0; i < c->n_ramps; i++) {
        if (c->ramp_from[i] <= along && along < c->ramp_to[i]) {
            g_sin = c->ramp_sin[i];
            g_cos = c->ramp_cos[i];
            break;
        }
    }
    if (g_sin == 0.0) {
        c->n_drive = c->n_drive0;
        c->n_caster = c->n_caster0;
        *gx = 0.0;
        *gy = 0.0;
        return;
    }
    double normal = c->mass_g * g_cos;
    double pull = c->mass_g * g_sin;
    double casters = (normal * c->cog_x + pull * (cs * c->down_c + sn * c->down_s) * c->cog_h) / c->caster_x;
    casters = clampd(casters, 0.0, normal);
    c->n_drive = 0.5 * (normal - casters);
    c->n_caster = 0.5 * casters;
    *gx = pull * c->down_c;
    *gy = pull * c->down_s;
}

/* The battery a step on (force_model.battery): the terminal voltage from the state of
 * charge and the driver's input current of the last step, the motors' volts from it,
 * then the charge it draws over the step. */
static void battery(chair_t *c, double dt) {
    if (c->bat_cap <= 0.0)
        return;
    double drawn = c->duty[0] * c->current[0] + c->duty[1] * c->current[1];
    c->bat_v = c->bat_e0 + (c->bat_e1 - c->bat_e0) * c->soc - c->bat_r * drawn;
    c->volts[0] = c->duty[0] * c->bat_v;
    c->volts[1] = c->duty[1] * c->bat_v;
    c->soc = clampd(c->soc - drawn * dt / c->bat_cap, 0.0, 1.0);
}

static void step(chair_t *c, int lone, double dt) {
    battery(c, dt);
    vec_t v = ((get_vec_fn)c->get_velocity)(c->body);
    double th = ((get_f_fn)c->get_angle)(c->body);
    double w = ((get_f_fn)c->get_angular_velocity)(c->body);
    double cs = cos(th), sn = sin(th), xg = c->cog_x;
    double ax = v.x + w * xg * sn, ay = v.y - w * xg * cs;
    double u = ax * cs + ay * sn;
    double lat = -ax * sn + ay * cs;
    double gx = 0.0, gy = 0.0;
    if (c->terrain) {
        vec_t pos = ((get_vec_fn)c->get_position)(c->body);
        grade(c, pos.x, pos.y, cs, sn, &gx, &gy);
    }
    double half = c->half_base;
    double f_left = wheel(c, 0, u - w * half, dt);
    double f_right = wheel(c, 1, u + w * half, dt);
    double fx_b = f_left + f_right, fy_b = 0.0;
    double torque_axle = (f_right - f_left) * half;
    double k_lat = c->k_lat;
    double ce_lat = c->c_lat + k_lat * dt;
    for (int i = 0; i < 2; i++) {
        /* the patch sideways as along (wheel()), within what the friction circle leaves */
        double lim = c->mu[i] * c->n_drive;
        double room = sqrt(fmax(0.0, lim * lim - c->force[i] * c->force[i]));
        fy_b += clampd(k_lat * c->defl_lat[i] + ce_lat * -lat, -room, room);
        c->defl_lat[i] = deflect(c->defl_lat[i], -lat, room * c->inv_k_lat, dt);
    }
    double xc = c->caster_x, d = c->trail, n_c = c->n_caster;
    int scrubbing = 0;
    for (int i = 0; i < 2; i++) {
        double yc = i == 0 ? c->caster_y : -c->caster_y;
        double pu = u - w * yc, pv = lat + w * xc;
        double psi = c->caster_heading[i] - th;
        double ce = cos(psi), se = sin(psi);
        double along_n = -pu * se + pv * ce;
        double rate = clampd(along_n / d, -c->swivel_max, c->swivel_max);
        double side_slip = along_n - d * rate;
        double limit = c->mu_c * n_c;
        double f_swivel = -c->swivel_friction * tanh(rate / SWIVEL_RATE_SCALE) / d;
        double f_side = clampd(f_swivel - c->c_caster * side_slip, -limit, limit);
        c->swivel_work += fabs(c->swivel_friction * tanh(rate / SWIVEL_RATE_SCALE) * rate) * dt;
        c->side_impulse += fabs(f_side) * dt;
        /* the patch carries its side force by sliding (force_model.py) */
        double slip = fabs(f_side) / c->c_caster;
        if (fabs(f_side) >= limit) slip = fmax(slip, fabs(side_slip));
        c->scrub_energy += fabs(f_side) * slip * dt;
        scrubbing = scrubbing || slip > SCRUB_SLIP;
        double roll = pu * ce + pv * se;
        double f_roll = -c->crr_c * n_c * tanh(roll / 0.01);
        double fxc = f_roll * ce - f_side * se;
        double fyc = f_roll * se + f_side * ce;
        double px = xc - d * ce, py = yc - d * se;
        fx_b += fxc;
        fy_b += fyc;
        torque_axle += px * fyc - py * fxc;
        c->caster_heading[i] += (w + rate) * dt;
    }
    if (scrubbing) c->scrub_time += dt;
    double torque_cog = torque_axle - xg * fy_b;
    vec_t f = {fx_b * cs - fy_b * sn, fx_b * sn + fy_b * cs};
    if (c->terrain) {
        f.x = fx_b * cs - fy_b * sn + gx;
        f.y = fx_b * sn + fy_b * cs + gy;
    }
    ((set_vec_fn)c->set_force)(c->body, f);
    ((set_f_fn)c->set_torque)(c->body, torque_cog);
    space_step(c, lone, dt);
    c->time += dt;
    if (c->has_brake && c->brake_engaged == c->brake_pin) {
        /* the brake is yet to follow its pin (released is pin 1, engaged 0) */
        c->brake_wait -= dt;
        if (c->brake_wait <= BRAKE_SLACK)
            c->brake_engaged = 1 - c->brake_pin;
    }
    if (c->th_cap > 0.0)
        for (int i = 0; i < 2; i++)
            c->temp[i] += dt * (c->current[i] * c->current[i] * c->res - (c->temp[i] - c->t_amb) / c->th_res)
                          / c->th_cap;
}

/* n steps; after each, the wheel angles (left, right) and the yaw rate are stored
 * in the output arrays when they are not NULL, and in motion (6 doubles a step) the
 * time at the step's end (t0 + dt (k + 1), as numpy computes it), the axle midpoint's
 * forward and lateral speed, the yaw rate and the motor voltages over the step
 * (Plant.start_motion_log). */
void chair_advance(chair_t *c, int32_t n, double dt, double t0, double *angles, double *yaw_rates,
                   double *motion) {
    int lone = n > 0 && lone_body(c);
    for (int32_t k = 0; k < n; k++) {
        step(c, lone, dt);
        if (angles) {
            angles[2 * k] = c->angle[0];
            angles[2 * k + 1] = c->angle[1];
        }
        double w = ((get_f_fn)c->get_angular_velocity)(c->body);
        if (yaw_rates) yaw_rates[k] = w;
        if (motion) {
            vec_t v = ((get_vec_fn)c->get_velocity)(c->body);
            double th = ((get_f_fn)c->get_angle)(c->body);
            double cs = cos(th), sn = sin(th), xg = c->cog_x;
            double ax = v.x + w * xg * sn, ay = v.y - w * xg * cs;
            motion[6 * k] = t0 + dt * (double)(k + 1);
            motion[6 * k + 1] = ax * cs + ay * sn;
            motion[6 * k + 2] = -ax * sn + ay * cs;
            motion[6 * k + 3] = w;
            motion[6 * k + 4] = c->volts[0];
            motion[6 * k + 5] = c->volts[1];
        }
    }
}

/* The gyro's samples (wcdrive.plant.sensors.Gyro.sample_steps) due by g[2] (t_end)
 * over n plant steps of g[4] (dt) from g[3] (t0) whose yaw rates are yaw_rates: from
 * g[0] (the next sample's time) on, every g[5] (period), while the time is <= t_end;
 * each sample takes two draws (the bias's random-walk step, scaled by g[6], then the
 * noise, scaled by g[7]) and the yaw rate of the step it falls in. The same operations,
 * in the same order, as Gyro.sample in Python. g[0] and g[1] (the bias) move on;
 * returns the number of samples written to times and values (at most max_samples). */
int32_t gyro_samples(int32_t n, double *g, const double *yaw_rates, const double *draws,
                     int32_t max_samples, double *times, double *values) {
    double t = g[0], bias = g[1], t_end = g[2], t0 = g[3], dt = g[4], period = g[5];
    double walk = g[6], noise = g[7];
    int32_t m = 0;
    while (t <= t_end && m < max_samples) {
        bias += walk * draws[2 * m];
        int64_t k = (int64_t)((t - t0) / dt - 1e-9);
        if (k > n - 1) k = n - 1;
        if (k < 0) k = 0;
        times[m] = t;
        values[m] = yaw_rates[k] + bias + noise * draws[2 * m + 1];
        m++;
        t += period;
    }
    g[0] = t;
    g[1] = bias;
    return m;
}

/* chair_advance for n steps from the plant's own time, then gyro_samples over them
 * with the yaw rates (which must not be NULL): one call for a control tick's steps and
 * the gyro's samples (wcdrive.plant.Plant.advance_batch with a sampler). g[2] (t_end),
 * g[3] (t0) and g[4] (dt) are set here, as Gyro.sample_steps sets them: no sample is
 * taken when the next one is due after t_end. Returns the number of samples. */
int32_t chair_advance_sampled(chair_t *c, int32_t n, double dt, double *angles, double *yaw_rates,
                              double *motion, double *g, const double *draws, int32_t max_samples,
                              double *times, double *values) {
    double t0 = c->time;
    chair_advance(c, n, dt, t0, angles, yaw_rates, motion);
    g[2] = t0 + dt * (double)n + 1e-12;
    g[3] = t0;
    g[4] = dt;
    if (n <= 0 || g[0] > g[2]) return 0;
    return gyro_samples(n, g, yaw_rates, draws, max_samples, times, values);
}

/* The layout of chair_t as compiled, for the check that the ctypes mirror
 * (wcdrive.plant.chair_kernel.ChairStruct) lays it out alike (wcdrive.plant.struct_layout,
 * whose docstring describes these records): each field's name, offset, size and kind,
 * from offsetof, sizeof and _Generic. A field added to chair_t is added here too: the
 * check refuses a mirror with a field this table lacks, and a table with a gap wider
 * than alignment explains. */
typedef struct { const char *name; size_t offset, size; char kind; } wc_field;
typedef struct {
    size_t layout_size, field_size;
    const char *name;
    size_t size, count;
    const wc_field *fields;
} wc_layout;
#define WC_KIND(x) _Generic((x), double: 'd', float: 'f', int32_t: 'i', uint32_t: 'I', int64_t: 'q', \
                            uint64_t: 'Q', default: 'p')
#define WC_FIELD(T, f) { #f, offsetof(T, f), sizeof(((T *)0)->f), WC_KIND(((T *)0)->f) }
#define WC_ARRAY(T, f) { #f, offsetof(T, f), sizeof(((T *)0)->f), WC_KIND(((T *)0)->f[0]) }
#define WC_LAYOUT(T, fields) { sizeof(wc_layout), sizeof(wc_field), #T, sizeof(T), \
                               sizeof fields / sizeof fields[0], fields }
#define F(f) WC_FIELD(chair_t, f)
#define A(f) WC_ARRAY(chair_t, f)

static const wc_field chair_fields[] = {
    F(half_base), F(r), F(cog_x), F(caster_x), F(caster_y), F(trail), F(swivel_max), F(swivel_friction),
    A(mu), F(mu_c), F(n_drive), F(n_caster), F(crr), F(crr_c), F(c_long), F(c_lat), F(c_caster),
    F(j), F(b), F(k1), F(k2), F(ke_g), F(tau_max), F(i_max_r), F(res),
    F(space), F(body),
    F(get_velocity), F(get_angle), F(get_angular_velocity), F(set_force), F(set_torque), F(space_step),
    F(update_position), F(update_velocity), F(get_damping), F(get_gravity), F(get_sleep_threshold),
    F(each_body), F(each_constraint), F(body_each_shape), F(get_body_type),
    A(volts),
    A(angle), A(speed), A(current), A(slip), A(force),
    A(caster_heading),
    F(scrub_energy), F(scrub_time), F(swivel_work), F(side_impulse), F(time),
    A(locked), A(dead),
    F(custom_funcs),
    F(terrain), F(n_ramps),
    F(mass_g), F(cog_h), F(n_drive0), F(n_caster0), F(down_c), F(down_s), F(slope_sin), F(slope_cos),
    A(ramp_from), A(ramp_to), A(ramp_sin), A(ramp_cos),
    F(get_position),
    F(k_long), F(k_lat), F(inv_k_long), F(inv_k_lat),
    A(defl), A(defl_lat),
    F(brake_torque), F(brake_wait),
    F(th_res), F(th_cap), F(t_amb), A(temp),
    F(bat_e0), F(bat_e1), F(bat_r), F(bat_cap), F(soc), F(bat_v), A(duty),
    F(has_brake), F(brake_pin), F(brake_engaged),
};
#undef F
#undef A

static const wc_layout layout = WC_LAYOUT(chair_t, chair_fields);

const wc_layout *chair_layout(void) { return &layout; }
