/* The lidar's ray cast over a world's static geometry (segments and circles), through a
 * uniform grid of cells: each ray walks the cells it crosses in order (DDA), testing the
 * items binned in each, and stops in the first cell it leaves past the nearest hit found.
 *
 * The distances are those of wcdrive.plant.world.World.cast_exact, operation for
 * operation (build with -ffp-contract=off): a segment is met at t >= 0 along the ray
 * where 0 <= u <= 1 along the segment (a ray parallel to it never meets it), a circle at
 * its near root, or its far one from inside; a ray meets nothing beyond max_range (inf);
 * a hit at the origin is +0.
 * The grid only chooses which items a ray tests: an item is binned into every cell its
 * geometry comes within `eps` of, so that a ray's walk, whose positions round, still
 * tests every item it can meet before it stops.
 *
 * Items: index k < n_seg is segment k, k >= n_seg circle k - n_seg. The grid is CSR:
 * cell (ix, iy) is c = iy * nx + ix and holds items[start[c] .. start[c + 1]), in
 * increasing order (so its segments before its circles).
 *
 * rc_scan makes one turn of a lidar (wcdrive.plant.lidar.Lidar.scan_numpy, the
 * reference) in one call: each sample's pose, its cast, its noise, its quarter
 * millimetres and the driver's binning into the published beams. rc_run does an
 * rc_job (a turn, its poses from a motion log or from knots); an rc_pipe does jobs
 * in order on a thread of its own.
 */
#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

/* fmin and fmax of figures that are never NaN (libm's calls cost more than the walk's steps) */
static inline double min2(double a, double b) { return a < b ? a : b; }
static inline double max2(double a, double b) { return a > b ? a : b; }

typedef struct {
    const double *seg;      /* n_seg x 4: x0, y0, x1, y1 */
    int32_t n_seg;
    const double *circ;     /* n_circ x 3: x, y, r */
    int32_t n_circ;
    double minx, miny;      /* the grid's lower-left corner */
    double cs, inv_cs;      /* cell size, its inverse */
    int32_t nx, ny;
    double eps;             /* how near an item must come to a cell to be binned in it */
    const int32_t *start;   /* nx * ny + 1 */
    int32_t *items;
    /* the cast's copy of the items, in the cells' order (rc_fill's, then the caller's):
     * rec[i] is item items[i] as x0, y0, x1 - x0, y1 - y0 (a segment) or x, y, r, 0 (a
     * circle); a cell's segments come first, up to seg_end[c] */
    const double *rec;
    const int32_t *seg_end;
} rc_grid;

static int seg_touches_box(const double *s, double bx0, double by0, double bx1, double by1,
                           double eps) {
    double x0 = s[0], y0 = s[1], x1 = s[2], y1 = s[3];
    if (fmax(x0, x1) < bx0 || fmin(x0, x1) > bx1 || fmax(y0, y1) < by0 || fmin(y0, y1) > by1)
        return 0;
    /* the box's corners all on one side of the segment's line, by more than eps: apart */
    double ex = x1 - x0, ey = y1 - y0;
    double tol = eps * (fabs(ex) + fabs(ey));
    double c[4];
    c[0] = ex * (by0 - y0) - ey * (bx0 - x0);
    c[1] = ex * (by0 - y0) - ey * (bx1 - x0);
    c[2] = ex * (by1 - y0) - ey * (bx0 - x0);
    c[3] = ex * (by1 - y0) - ey * (bx1 - x0);
    int above = 0, below = 0;
    for (int i = 0; i < 4; i++) {
        above += c[i] > tol;
        below += c[i] < -tol;
    }
    return above < 4 && below < 4;
}

/* the cell at v cells from the grid's edge, within 0 .. n - 1 (a truncation, which is
 * floor where it is not clamped) */
static int clamp_cell(double v, int32_t n) {
    if (!(v >= 0.0)) return 0;
    if (v >= (double)(n - 1)) return n - 1;
    return (int)v;
}

/* Bins the items into the grid: with `items` NULL counts each cell's items into
 * counts[c]; else writes them at items[counts[c]++] (counts then the cells' starts). */
static void bin(const rc_grid *g, int32_t *counts, int32_t *items) {
    int32_t n = g->n_seg + g->n_circ;
    for (int32_t k = 0; k < n; k++) {
        double lox, loy, hix, hiy;
        const double *s = 0;
        if (k < g->n_seg) {
            s = g->seg + 4 * k;
            lox = fmin(s[0], s[2]); hix = fmax(s[0], s[2]);
            loy = fmin(s[1], s[3]); hiy = fmax(s[1], s[3]);
        } else {
            const double *c = g->circ + 3 * (k - g->n_seg);
            lox = c[0] - c[2]; hix = c[0] + c[2];
            loy = c[1] - c[2]; hiy = c[1] + c[2];
        }
        int ix0 = clamp_cell((lox - g->eps - g->minx) * g->inv_cs, g->nx);
        int ix1 = clamp_cell((hix + g->eps - g->minx) * g->inv_cs, g->nx);
        int iy0 = clamp_cell((loy - g->eps - g->miny) * g->inv_cs, g->ny);
        int iy1 = clamp_cell((hiy + g->eps - g->miny) * g->inv_cs, g->ny);
        for (int iy = iy0; iy <= iy1; iy++) {
            for (int ix = ix0; ix <= ix1; ix++) {
                if (s) {
                    double bx0 = g->minx + ix * g->cs - g->eps, by0 = g->miny + iy * g->cs - g->eps;
                    if (!seg_touches_box(s, bx0, by0, bx0 + g->cs + 2 * g->eps, by0 + g->cs + 2 * g->eps,
                                         g->eps))
                        continue;
                }
                int32_t c = iy * g->nx + ix;
                if (items)
                    items[counts[c]++] = k;
                else
                    counts[c]++;
            }
        }
    }
}

/* counts: nx * ny, zeroed. */
void rc_count(const rc_grid *g, int32_t *counts) { bin(g, counts, 0); }

/* next: a copy of the cells' starts (start[0 .. nx * ny)), used up. */
void rc_fill(const rc_grid *g, int32_t *next) { bin(g, next, g->items); }

static double cast_one(const rc_grid *g, double ox, double oy, double dx, double dy, double max_range) {
    if (!(isfinite(ox) && isfinite(oy) && isfinite(dx) && isfinite(dy)))
        return INFINITY;
    const double minx = g->minx, miny = g->miny, cs = g->cs;
    const double maxx = minx + g->nx * cs, maxy = miny + g->ny * cs;
    /* the walk's directions: a component too small to step along counts as 0 */
    int sx = dx > 1e-300 ? 1 : dx < -1e-300 ? -1 : 0;
    int sy = dy > 1e-300 ? 1 : dy < -1e-300 ? -1 : 0;
    double inv_dx, inv_dy;
    if (sx && sy && fabs(dx * dy) > 1e-290) {
        double inv = 1.0 / (dx * dy);           /* one division for both */
        inv_dx = dy * inv;
        inv_dy = dx * inv;
    } else {
        inv_dx = sx ? 1.0 / dx : 0.0;
        inv_dy = sy ? 1.0 / dy : 0.0;
    }
    /* the part of the ray inside the grid (from 0 where the origin is inside) */
    double t0 = 0.0, t1 = INFINITY;
    if (!(ox >= minx && ox <= maxx && oy >= miny && oy <= maxy)) {
        if (sx) {
            double a = (minx - ox) * inv_dx, b = (maxx - ox) * inv_dx;
            t0 = max2(t0, min2(a, b));
            t1 = min2(t1, max2(a, b));
        } else if (ox < minx || ox > maxx) {
            return INFINITY;
        }
        if (sy) {
            double a = (miny - oy) * inv_dy, b = (maxy - oy) * inv_dy;
            t0 = max2(t0, min2(a, b));
            t1 = min2(t1, max2(a, b));
        } else if (oy < miny || oy > maxy) {
            return INFINITY;
        }
    }
    /* beyond `limit` no hit can be within max_range */
    double limit = max_range + g->eps + 1e-12 * fabs(max_range);
    if (t0 > t1 || t0 > limit)
        return INFINITY;
    int ix = clamp_cell((ox + t0 * dx - minx) * g->inv_cs, g->nx);
    int iy = clamp_cell((oy + t0 * dy - miny) * g->inv_cs, g->ny);
    double best = INFINITY;
    /* where the ray leaves the first cell across x and across y, and how far on it
     * crosses the next column and row: the sums round, far below eps */
    double tx = sx > 0 ? (minx + (ix + 1) * cs - ox) * inv_dx
              : sx < 0 ? (minx + ix * cs - ox) * inv_dx : INFINITY;
    double ty = sy > 0 ? (miny + (iy + 1) * cs - oy) * inv_dy
              : sy < 0 ? (miny + iy * cs - oy) * inv_dy : INFINITY;
    const double step_x = sx ? cs * fabs(inv_dx) : INFINITY, step_y = sy ? cs * fabs(inv_dy) : INFINITY;
    for (;;) {
        double texit = min2(tx, ty);
        int32_t c = iy * g->nx + ix;
        /* the cell's segments, then its circles, each a record of four */
        int32_t i = g->start[c], mid = g->seg_end[c], end = g->start[c + 1];
        for (; i < mid; i++) {
            const double *s = g->rec + 4 * (ptrdiff_t)i;
            double ex = s[2], ey = s[3];
            double denom = dx * ey - dy * ex;
            if (denom == 0.0)
                continue;
            double wx = s[0] - ox, wy = s[1] - oy;
            double tn = wx * ey - wy * ex, un = wx * dy - wy * dx;
            /* the quotients' signs and sizes without dividing, with margins that keep
             * every candidate the divided figures would take */
            double a = fabs(denom), st = denom < 0.0 ? -tn : tn, su = denom < 0.0 ? -un : un;
            if (st < -a * 0x1p-1000 || su < -a * 0x1p-1000 || su > a * (1.0 + 0x1p-50)
                    || st > best * a * (1.0 + 0x1p-50))
                continue;
            double t = tn / denom;
            double u = un / denom;
            if (t >= 0.0 && u >= 0.0 && u <= 1.0 && t < best)
                best = t;
        }
        for (; i < end; i++) {
            const double *q = g->rec + 4 * (ptrdiff_t)i;
            double fx = ox - q[0], fy = oy - q[1], r = q[2];
            double b = fx * dx + fy * dy;
            double cc = fx * fx + fy * fy - r * r;
            double disc = b * b - cc;
            if (!(disc >= 0.0))
                continue;
            double root = sqrt(disc);
            double t_near = -b - root, t_far = -b + root;
            double t = t_near >= 0.0 ? t_near : t_far;
            if (t >= 0.0 && t < best)
                best = t;
        }
        if (best <= texit || texit > limit)
            break;
        /* the step across x or across y, chosen without a branch (which way it goes
         * is a coin toss on a slanted ray) */
        int across_x = tx < ty;
        ix += across_x ? sx : 0;
        iy += across_x ? 0 : sy;
        tx = across_x ? tx + step_x : tx;
        ty = across_x ? ty : ty + step_y;
        if ((uint32_t)ix >= (uint32_t)g->nx || (uint32_t)iy >= (uint32_t)g->ny)
            break;
    }
    return best <= max_range ? best + 0.0 : INFINITY;    /* + 0.0: a hit at -0 is at 0 */
}

/* out[i]: ray i's distance to the first item it meets within max_range, else inf; ray
 * i from (ox[i], oy[i]) along the unit vector (dx[i], dy[i]). */
void rc_cast(const rc_grid *g, int32_t n, const double *ox, const double *oy, const double *dx,
             const double *dy, double max_range, double *out) {
    for (int32_t i = 0; i < n; i++)
        out[i] = cast_one(g, ox[i], oy[i], dx[i], dy[i], max_range);
}

/* A lidar and its driver (wcdrive.plant.lidar): the turn's samples, each taken at
 * t0 + offset[j] along the device direction (cos, sin)[j] of the chair's frame
 * (the mount's yaw and the head's turn in it), from (mount_x, mount_y) on the chair. */
typedef struct {
    int32_t samples;
    const double *offset;   /* samples: j / sample_hz */
    const double *device;   /* samples x 2: the direction of sample j in the chair's frame */
    const int32_t *first_bin;   /* samples: the driver's first bin of sample j */
    int32_t beams, multiple;
    double mount_x, mount_y;
    double sigma;           /* range noise (m) on the draws `noise` */
    double device_min, range_max;
    float intensity;
    int32_t reverse;        /* publish the bins last first (the driver not told "inverted") */
} rc_lidar;

/* cos and sin of a small angle (|d| < 0.05: within an ulp or two of libm's) */
static void small_rotation(double d, double *c, double *s) {
    double d2 = d * d;
    *c = 1.0 - d2 * (0.5 - d2 * (1.0 / 24 - d2 * (1.0 / 720 - d2 * (1.0 / 40320))));
    *s = d * (1.0 - d2 * (1.0 / 6 - d2 * (1.0 / 120 - d2 * (1.0 / 5040 - d2 * (1.0 / 362880)))));
}

/* The chair's poses from the pose at t0 and the plant's motion log (rows of `stride`
 * doubles: time, forward, lateral, yaw rate, ...): knots t, x, y, h (n + 1 each), as
 * wcdrive.plant.lidar.MotionTrack integrates them (the heading's step at its midpoint). */
void rc_integrate(double t0, double x0, double y0, double h0, int32_t n, const double *log,
                  int32_t stride, double *t, double *x, double *y, double *h) {
    double ch = 0.0, cx = 0.0, cy = 0.0;
    t[0] = t0; x[0] = x0; y[0] = y0; h[0] = h0;
    for (int32_t k = 0; k < n; k++) {
        const double *r = log + (ptrdiff_t)k * stride;
        double dt = r[0] - t[k];
        double turn = r[3] * dt;
        ch += turn;
        t[k + 1] = r[0];
        h[k + 1] = h0 + ch;
        double mid = h[k + 1] - turn / 2;
        double c = cos(mid), s = sin(mid);
        cx += (r[1] * c - r[2] * s) * dt;
        cy += (r[1] * s + r[2] * c) * dt;
        x[k + 1] = x0 + cx;
        y[k + 1] = y0 + cy;
    }
}

/* rc_scan: one turn from t0: sample j's pose interpolated in the knots (kt increasing, n >= 1;
 * np.interp's rule: held at the ends), its ray cast, its noise (noise[j] * sigma, none
 * without `noise`), its range in quarter millimetres (0: none, below device_min or
 * above range_max), and the driver's bins: ranges (float32 m, inf for none),
 * intensities and beam_time (the time of the sample in each bin, NaN for none), each
 * `beams` long. q2: `samples` int32, each sample's quarter millimetres. */
/* rc_scan's samples j0 .. j1 - 1, into q2 */
static void scan_samples(const rc_grid *g, const rc_lidar *L, double t0, int32_t n, const double *kt,
                         const double *kx, const double *ky, const double *kh, const double *noise,
                         int32_t j0, int32_t j1, int32_t *q2) {
    /* the last knot at or before the first sample (0 for none) */
    int32_t k = 0;
    if (j0 < j1) {
        int32_t lo = 0, hi = n;                 /* kt[lo] <= t < kt[hi], as far as known */
        double t = t0 + L->offset[j0];
        while (hi - lo > 1) {
            int32_t m = lo + (hi - lo) / 2;
            if (kt[m] <= t) lo = m; else hi = m;
        }
        k = lo;
    }
    double slope_x = 0.0, slope_y = 0.0, slope_h = 0.0, ck = 1.0, sk = 0.0;
    int32_t at = -1, sloped = -1;         /* the knots ck, sk and the slopes belong to */
    for (int32_t j = j0; j < j1; j++) {
        double tj = t0 + L->offset[j];
        while (k < n - 1 && kt[k + 1] <= tj)
            k++;
        double x, y, h, dh;
        if (tj < kt[0]) {
            x = kx[0]; y = ky[0]; h = kh[0]; dh = 0.0; k = 0;
        } else if (k == n - 1 || kt[k] == tj) {
            x = kx[k]; y = ky[k]; h = kh[k]; dh = 0.0;
        } else {
            if (sloped != k) {
                sloped = k;
                double inv = 1.0 / (kt[k + 1] - kt[k]);
                slope_x = (kx[k + 1] - kx[k]) * inv;
                slope_y = (ky[k + 1] - ky[k]) * inv;
                slope_h = (kh[k + 1] - kh[k]) * inv;
            }
            double u = tj - kt[k];
            x = slope_x * u + kx[k];
            y = slope_y * u + ky[k];
            h = slope_h * u + kh[k];
            dh = h - kh[k];
        }
        /* the heading's cos and sin: the knot's, turned by the small step from it */
        double c, s;
        if (at != k) {
            ck = cos(kh[k]);
            sk = sin(kh[k]);
            at = k;
        }
        if (fabs(dh) < 0.05) {
            double cd, sd;
            small_rotation(dh, &cd, &sd);
            c = ck * cd - sk * sd;
            s = sk * cd + ck * sd;
        } else {
            c = cos(h);
            s = sin(h);
        }
        double ox = x + c * L->mount_x - s * L->mount_y;
        double oy = y + s * L->mount_x + c * L->mount_y;
        const double *d = L->device + 2 * j;
        double dx = c * d[0] - s * d[1], dy = s * d[0] + c * d[1];
        double r = cast_one(g, ox, oy, dx, dy, INFINITY);
        if (noise)
            r = r + (0.0 + L->sigma * noise[j]);
        /* to the nearest quarter millimetre, ties to even (2^52 added and taken off:
         * the default rounding, for 0 <= r * 4000 < 2^51) */
        q2[j] = isfinite(r) && r >= L->device_min && r <= L->range_max
                ? (int32_t)((r * 4000.0 + 0x1p52) - 0x1p52) : 0;
    }
}

/* rc_scan's bins from the samples' q2 */
static void bin_samples(const rc_lidar *L, double t0, const int32_t *q2, float *ranges, float *intensities,
                        double *beam_time) {
    /* the driver's angle_compensate: sample j with a return fills the `multiple` bins
     * from its first on (the last bin for any past the end), later samples over earlier.
     * The first bins rise with j: taken last first, a sample fills its bins below the
     * lowest a later one filled (`hi`), each bin once. */
    for (int32_t b = 0; b < L->beams; b++) {
        ranges[b] = INFINITY;
        intensities[b] = 0.0f;
        beam_time[b] = NAN;
    }
    int32_t hi = L->beams;
    for (int32_t j = L->samples - 1; j >= 0; j--) {
        if (q2[j] == 0)
            continue;
        int32_t lo = L->first_bin[j], top = lo + L->multiple - 1;
        if (lo < 0)
            lo = 0;
        if (top > L->beams - 1)
            top = L->beams - 1;
        if (top > hi - 1)
            top = hi - 1;
        float range = ((float)q2[j] / 4.0f) / 1000.0f;
        double tj = t0 + L->offset[j];
        for (int32_t b = lo; b <= top; b++) {
            int32_t out = L->reverse ? L->beams - 1 - b : b;
            ranges[out] = range;
            intensities[out] = L->intensity;
            beam_time[out] = tj;
        }
        if (lo < hi)
            hi = lo;
    }
}

void rc_scan(const rc_grid *g, const rc_lidar *L, double t0, int32_t n, const double *kt,
             const double *kx, const double *ky, const double *kh, const double *noise,
             int32_t *q2, float *ranges, float *intensities, double *beam_time) {
    scan_samples(g, L, t0, n, kt, kx, ky, kh, noise, 0, L->samples, q2);
    bin_samples(L, t0, q2, ranges, intensities, beam_time);
}

/* One turn to make: its poses from knots kt, kx, ky, kh (n of them) or, with `log`,
 * from the motion log's rows integrated from (start_x, start_y, start_h) at t0 into
 * them (n = log_rows + 1, the knots written); then rc_scan into q2 .. beam_time.
 * The rest is the pipe's: where the job is (JOB_QUEUED .. JOB_DONE), its samples
 * handed out in chunks (the next to hand out, those not finished), the queue. */
typedef struct rc_job {
    const rc_grid *grid;
    const rc_lidar *lidar;
    double t0;
    int32_t n;
    double *kt, *kx, *ky, *kh;
    const double *log;
    int32_t log_rows, log_stride;
    double start_x, start_y, start_h;
    const double *noise;
    int32_t *q2;
    float *ranges, *intensities;
    double *beam_time;
    int32_t state, next_chunk, chunks_left;
    struct rc_job *next;
} rc_job;

enum { JOB_QUEUED, JOB_STARTING, JOB_CHUNKS, JOB_DONE };
/* samples in a chunk: a few tens of microseconds of work */
#define CHUNK 256

static void integrate_job(rc_job *job) {
    if (job->log)
        rc_integrate(job->t0, job->start_x, job->start_y, job->start_h, job->log_rows, job->log,
                     job->log_stride, job->kt, job->kx, job->ky, job->kh);
}

static void scan_chunk(rc_job *job, int32_t chunk) {
    int32_t j0 = chunk * CHUNK, j1 = j0 + CHUNK < job->lidar->samples ? j0 + CHUNK : job->lidar->samples;
    scan_samples(job->grid, job->lidar, job->t0, job->n, job->kt, job->kx, job->ky, job->kh, job->noise,
                 j0, j1, job->q2);
}

static void bin_job(rc_job *job) {
    bin_samples(job->lidar, job->t0, job->q2, job->ranges, job->intensities, job->beam_time);
}

void rc_run(rc_job *job) {
    integrate_job(job);
    rc_scan(job->grid, job->lidar, job->t0, job->n, job->kt, job->kx, job->ky, job->kh, job->noise,
            job->q2, job->ranges, job->intensities, job->beam_time);
    job->state = JOB_DONE;
}

/* A thread that makes the jobs submitted to it in order; a caller waiting for a job
 * makes chunks of its samples too (or the whole job, if the thread has not started
 * it), so that both make it. A job's memory (and all it points to) is the caller's,
 * untouched by the caller from rc_pipe_submit until rc_pipe_wait has returned for it. */
typedef struct {
    pthread_t thread;
    pthread_mutex_t lock;
    pthread_cond_t work, finished;
    rc_job *head, *tail;
    int closing;
} rc_pipe;

/* With the lock held (and held again on return): makes the job's chunks not yet
 * handed out; whoever finishes its last chunk bins it and marks it done. */
static void make_chunks(rc_pipe *p, rc_job *job) {
    while (job->state == JOB_CHUNKS && job->next_chunk * CHUNK < job->lidar->samples) {
        int32_t chunk = job->next_chunk++;
        pthread_mutex_unlock(&p->lock);
        scan_chunk(job, chunk);
        pthread_mutex_lock(&p->lock);
        if (--job->chunks_left == 0) {
            pthread_mutex_unlock(&p->lock);
            bin_job(job);
            pthread_mutex_lock(&p->lock);
            job->state = JOB_DONE;
            pthread_cond_broadcast(&p->finished);
        }
    }
}

/* With the lock held: takes a queued job out of the queue, integrates its poses and
 * opens its chunks. */
static void start_job(rc_pipe *p, rc_job *job) {
    rc_job **at = &p->head, *before = 0;
    while (*at && *at != job) {
        before = *at;
        at = &(*at)->next;
    }
    if (*at) {
        *at = job->next;
        if (p->tail == job)
            p->tail = before;
    }
    job->state = JOB_STARTING;
    pthread_mutex_unlock(&p->lock);
    integrate_job(job);
    pthread_mutex_lock(&p->lock);
    job->next_chunk = 0;
    job->chunks_left = (job->lidar->samples + CHUNK - 1) / CHUNK;
    job->state = JOB_CHUNKS;
    if (job->chunks_left == 0) {
        pthread_mutex_unlock(&p->lock);
        bin_job(job);
        pthread_mutex_lock(&p->lock);
        job->state = JOB_DONE;
    }
    pthread_cond_broadcast(&p->finished);
}

static void *pipe_main(void *arg) {
    rc_pipe *p = arg;
    pthread_mutex_lock(&p->lock);
    for (;;) {
        while (!p->head && !p->closing)
            pthread_cond_wait(&p->work, &p->lock);
        rc_job *job = p->head;
        if (!job)
            break;                                  /* closing, and nothing left to do */
        start_job(p, job);
        make_chunks(p, job);
    }
    pthread_mutex_unlock(&p->lock);
    return 0;
}

/* A pipe with its thread started; NULL when it cannot be had. */
rc_pipe *rc_pipe_open(void) {
    rc_pipe *p = calloc(1, sizeof *p);
    if (!p)
        return 0;
    if (pthread_mutex_init(&p->lock, 0) != 0) {
        free(p);
        return 0;
    }
    if (pthread_cond_init(&p->work, 0) != 0 || pthread_cond_init(&p->finished, 0) != 0
            || pthread_create(&p->thread, 0, pipe_main, p) != 0) {
        /* the conditions need no destroying here: neither was waited on */
        pthread_mutex_destroy(&p->lock);
        free(p);
        return 0;
    }
    return p;
}

void rc_pipe_submit(rc_pipe *p, rc_job *job) {
    job->state = JOB_QUEUED;
    job->next = 0;
    pthread_mutex_lock(&p->lock);
    if (p->tail)
        p->tail->next = job;
    else
        p->head = job;
    p->tail = job;
    pthread_cond_signal(&p->work);
    pthread_mutex_unlock(&p->lock);
}

/* Returns once the job is done, making what is left of it meanwhile. */
void rc_pipe_wait(rc_pipe *p, rc_job *job) {
    pthread_mutex_lock(&p->lock);
    while (job->state != JOB_DONE) {
        if (job->state == JOB_QUEUED)
            start_job(p, job);
        make_chunks(p, job);
        if (job->state != JOB_DONE)
            pthread_cond_wait(&p->finished, &p->lock);
    }
    pthread_mutex_unlock(&p->lock);
}

/* Runs the jobs still queued, stops the thread and frees the pipe. */
void rc_pipe_close(rc_pipe *p) {
    pthread_mutex_lock(&p->lock);
    p->closing = 1;
    pthread_cond_signal(&p->work);
    pthread_mutex_unlock(&p->lock);
    pthread_join(p->thread, 0);
    pthread_cond_destroy(&p->work);
    pthread_cond_destroy(&p->finished);
    pthread_mutex_destroy(&p->lock);
    free(p);
}
