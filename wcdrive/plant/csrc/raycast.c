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
#include <time.h>
#ifdef WC_NPYRANDOM
/* numpy's own generator of standard normal draws (its libnpyrandom.a), on a
 * numpy.random.Generator's bit generator: the very draws of Generator.standard_normal */
#include <numpy/random/bitgen.h>
double random_standard_normal(bitgen_t *bitgen_state);
#endif

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
    /* the items' records again, in the items' order (a turn's fan reads them) */
    const double *item_rec;
    int32_t fan_bins;       /* a turn's fan: its direction bins (0: each ray walks the grid) */
    double scale;           /* the geometry's largest coordinate, 1 at least */
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

/* best, or the distance along the ray (ox, oy) + t (dx, dy) at which it meets the
 * segment whose record is s (x0, y0, x1 - x0, y1 - y0), if that is less */
static inline double meet_segment(const double *s, double ox, double oy, double dx, double dy, double best) {
    double ex = s[2], ey = s[3];
    double denom = dx * ey - dy * ex;
    if (denom == 0.0)
        return best;
    double wx = s[0] - ox, wy = s[1] - oy;
    double tn = wx * ey - wy * ex, un = wx * dy - wy * dx;
    /* the quotients' signs and sizes without dividing, with margins that keep every
     * candidate the divided figures would take */
    double a = fabs(denom), st = denom < 0.0 ? -tn : tn, su = denom < 0.0 ? -un : un;
    if (st < -a * 0x1p-1000 || su < -a * 0x1p-1000 || su > a * (1.0 + 0x1p-50)
            || st > best * a * (1.0 + 0x1p-50))
        return best;
    double t = tn / denom;
    /* u = un / denom is within 0 .. 1 wherever 0 <= su <= a: divided only outside */
    if (!(su >= 0.0 && su <= a)) {
        double u = un / denom;
        if (!(u >= 0.0 && u <= 1.0))
            return best;
    }
    return t >= 0.0 && t < best ? t : best;
}

/* the same for the circle whose record is q (x, y, r, 0): its near root, or its far
 * one from inside */
static inline double meet_circle(const double *q, double ox, double oy, double dx, double dy, double best) {
    double fx = ox - q[0], fy = oy - q[1], r = q[2];
    double b = fx * dx + fy * dy;
    double cc = fx * fx + fy * fy - r * r;
    double disc = b * b - cc;
    if (!(disc >= 0.0))
        return best;
    double root = sqrt(disc);
    double t_near = -b - root, t_far = -b + root;
    double t = t_near >= 0.0 ? t_near : t_far;
    return t >= 0.0 && t < best ? t : best;
}

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
        for (; i < mid; i++)
            best = meet_segment(g->rec + 4 * (ptrdiff_t)i, ox, oy, dx, dy, best);
        for (; i < end; i++)
            best = meet_circle(g->rec + 4 * (ptrdiff_t)i, ox, oy, dx, dy, best);
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

/* A turn's fan: the items its rays can meet, listed by the ray's direction.
 *
 * Directions are pseudo-angles: (x, y) -> [0, 4), rising with the angle, a quarter
 * turn a unit, at 1/2 to 1 unit a radian (so an angle widened by w radians is widened
 * by w units at most). The circle of directions is cut into `bins` bins, and those into
 * FAN_GROUPS groups. A ray goes to its direction's bin; a lidar's head turns steadily,
 * so the rays of one group come from a short stretch of the turn, and their origins
 * lie within a small radius of a centre (the box around them: its middle, its half
 * diagonal).
 *
 * A ray from within radius R of a centre meets an item only along a direction within
 * the item's angle seen from the centre widened by asin(R / d), d the item's distance
 * from the centre, and at least d - R from its origin (its `near`). So each item goes
 * into the bins of each group its angle reaches (first from the centre and radius of
 * all the turn's rays, then from the group's own), and a bin lists its items in rising
 * order of their near from the whole turn's centre, each entry bounded by the least
 * near (from its group's centre) of it and every later one. A ray tests its bin's
 * entries in order until the nearest hit found is below the next entry's bound: it
 * meets the same first item as the walk, at the same distance, as both test it alike.
 * An item within R (and rounding) of a centre is in every bin of that group, near 0.
 */
#ifndef FAN_GROUPS
#define FAN_GROUPS 8
#endif
#define FAN_LEVEL 0.01       /* m: the steps in which items are ordered by their near */
#ifndef FAN_LEVELS
#define FAN_LEVELS 1024
#endif
/* A fan is built only for a world of at most FAN_ITEMS_PER_SAMPLE items a sample of the
 * turn (its cost grows with the world, the walk's with the cells a ray crosses: on
 * tb3_sandbox's outline, 756 items, 0.13 ms a turn against the walk's 0.27; tiled 3 x
 * 3, 6,804 items, 0.43 against 0.25), of at most FAN_MAX_ENTRIES entries. */
#define FAN_ITEMS_PER_SAMPLE 0.5
#define FAN_MAX_ENTRIES (1 << 24)

/* a figure at or above asin(x), 0 <= x < 1: its tangent */
static inline double asin_above(double x) {
    return x / sqrt(1.0 - x * x) * (1.0 + 1e-9);
}

/* floor(x) for |x| < 2^31, as an integer (libm's floor is a call) */
static inline int32_t floor_int(double x) {
    int32_t i = (int32_t)x;
    return i - (x < (double)i);
}

static inline double pseudo_angle(double x, double y) {
    double p = y / (fabs(x) + fabs(y));     /* -1 .. 1 */
    return x < 0.0 ? 2.0 - p : p < 0.0 ? 4.0 + p : p;
}

/* An item's angle from (cx, cy) widened for `radius`, in pseudo-angle units lo .. hi
 * (hi - lo >= 4: every direction), and its near. */
static void item_extent(const rc_grid *g, int32_t k, double cx, double cy, double radius, double margin,
                        double *lo, double *hi, double *near) {
    const double *r = g->item_rec + 4 * (ptrdiff_t)k;
    double d, half, ang_lo, ang_hi;
    double ax = r[0] - cx, ay = r[1] - cy;
    if (k < g->n_seg) {
        double ex = r[2], ey = r[3];
        double bx = ax + ex, by = ay + ey;
        double len2 = ex * ex + ey * ey;
        double u = len2 > 0.0 ? -(ax * ex + ay * ey) / len2 : 0.0;
        u = u < 0.0 ? 0.0 : u > 1.0 ? 1.0 : u;
        double px = ax + u * ex, py = ay + u * ey;
        d = sqrt(px * px + py * py);
        *near = d - radius - 2.0 * margin;
        if (!(*near > 0.0)) {
            *lo = 0.0; *hi = 4.0; *near = 0.0;
            return;
        }
        double pa = pseudo_angle(ax, ay), pb = pseudo_angle(bx, by);
        if (ax * by - ay * bx >= 0.0) {     /* b counterclockwise of a */
            ang_lo = pa; ang_hi = pb;
        } else {
            ang_lo = pb; ang_hi = pa;
        }
        if (ang_hi < ang_lo)
            ang_hi += 4.0;
        half = 0.0;
    } else {
        double dc = sqrt(ax * ax + ay * ay);
        d = dc - r[2];
        *near = d - radius - 2.0 * margin;
        if (!(*near > 0.0)) {
            *lo = 0.0; *hi = 4.0; *near = 0.0;
            return;
        }
        ang_lo = ang_hi = pseudo_angle(ax, ay);
        half = asin_above(r[2] / (dc - radius - margin));   /* the circle's half angle from an origin */
    }
    double w = asin_above((radius + margin) / (d - margin)) + 1e-9;
    *lo = ang_lo - half - w;
    *hi = ang_hi + half + w;
}

/* A turn's rays (its samples' origins and directions, as cast) and its fan. */
typedef struct {
    double *ox, *oy, *dx, *dy;
    int32_t *bin;               /* each ray's bin; -1: the ray walks the grid */
    int32_t bins;               /* 0: no fan, every ray walks the grid */
    int32_t *start;             /* bins + 1: bin b's entries are start[b] .. start[b + 1] */
    int32_t *entry;             /* the entries' items */
    double *bound;              /* the entries' bounds */
} rc_rays;

/* one item's bins in one group: lo .. hi, its near from the group's centre */
typedef struct {
    int32_t item, lo, hi;
    double near;
} fan_span;

typedef struct {
    fan_span *at;
    size_t n, cap;
} fan_spans;

static int spans_add(fan_spans *s, int32_t item, int32_t lo, int32_t hi, double near) {
    if (s->n == s->cap) {
        size_t cap = s->cap ? 2 * s->cap : 1024;
        fan_span *at = realloc(s->at, cap * sizeof *at);
        if (!at)
            return 0;
        s->at = at;
        s->cap = cap;
    }
    s->at[s->n++] = (fan_span){item, lo, hi, near};
    return 1;
}

/* The fan of the rays (their bins set, -1 for a ray that walks the grid: one whose
 * figures are not finite or whose direction is not a unit vector); 0 when it cannot be
 * had (every ray then walks the grid). */
static int fan_build(rc_rays *w, const rc_grid *g, int32_t samples) {
    int32_t bins = w->bins, per_group = bins / FAN_GROUPS;
    double box[FAN_GROUPS][4], all[4] = {INFINITY, INFINITY, -INFINITY, -INFINITY};
    double gcx[FAN_GROUPS], gcy[FAN_GROUPS], grad[FAN_GROUPS];
    int32_t used[FAN_GROUPS] = {0};
    for (int32_t q = 0; q < FAN_GROUPS; q++) {
        box[q][0] = box[q][1] = INFINITY;
        box[q][2] = box[q][3] = -INFINITY;
    }
    double per_unit = bins * 0.25;
    /* the rays' bins, and the box around each group's origins (kept in hand while
     * the rays stay in one group, as they mostly do) */
    int32_t at = -1;
    double x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
    for (int32_t j = 0; j <= samples; j++) {
        int32_t b = -1, q = -1;
        if (j < samples) {
            double ox = w->ox[j], oy = w->oy[j], dx = w->dx[j], dy = w->dy[j];
            /* the bounds hold for unit directions: any other walks (as one not finite) */
            if (!(isfinite(ox) && isfinite(oy) && fabs(dx * dx + dy * dy - 1.0) <= 1e-12)) {
                w->bin[j] = -1;
                continue;
            }
            b = (int32_t)(pseudo_angle(dx, dy) * per_unit);
            b = b < 0 ? 0 : b >= bins ? bins - 1 : b;
            w->bin[j] = b;
            q = b / per_group;
            if (q == at) {
                x0 = min2(x0, ox); y0 = min2(y0, oy);
                x1 = max2(x1, ox); y1 = max2(y1, oy);
                continue;
            }
        }
        if (at >= 0) {
            double *r = box[at];
            r[0] = min2(r[0], x0); r[1] = min2(r[1], y0);
            r[2] = max2(r[2], x1); r[3] = max2(r[3], y1);
            used[at] = 1;
        }
        if (j < samples) {
            at = q;
            x0 = x1 = w->ox[j];
            y0 = y1 = w->oy[j];
        }
    }
    for (int32_t q = 0; q < FAN_GROUPS; q++) {
        if (!used[q])
            continue;
        all[0] = min2(all[0], box[q][0]); all[1] = min2(all[1], box[q][1]);
        all[2] = max2(all[2], box[q][2]); all[3] = max2(all[3], box[q][3]);
        gcx[q] = 0.5 * (box[q][0] + box[q][2]);
        gcy[q] = 0.5 * (box[q][1] + box[q][3]);
        grad[q] = 0.5 * hypot(box[q][2] - box[q][0], box[q][3] - box[q][1]) * (1.0 + 1e-9);
    }
    w->start = 0; w->entry = 0; w->bound = 0;
    if (!(all[0] <= all[2]))
        return 0;                   /* no ray with a bin */
    double cx = 0.5 * (all[0] + all[2]), cy = 0.5 * (all[1] + all[3]);
    double radius = 0.5 * hypot(all[2] - all[0], all[3] - all[1]) * (1.0 + 1e-9);
    double margin = 1e-9 * g->scale;
    int32_t items = g->n_seg + g->n_circ;
    /* the items in rising order of their near from the turn's centre */
    int32_t *level = malloc(sizeof(int32_t) * ((size_t)items * 2 + FAN_LEVELS + 1));
    double *lo = malloc(sizeof(double) * (size_t)items * 2);
    fan_spans spans = {0, 0, 0};
    w->start = calloc((size_t)bins + 1, sizeof(int32_t));
    if (!level || !lo || !w->start)
        goto fail;
    int32_t *order = level + items, *level_start = order + items;
    double *hi = lo + items;
    for (int32_t v = 0; v <= FAN_LEVELS; v++)
        level_start[v] = 0;
    for (int32_t k = 0; k < items; k++) {
        double near;
        item_extent(g, k, cx, cy, radius, margin, &lo[k], &hi[k], &near);
        double v = near * (1.0 / FAN_LEVEL);
        level[k] = !(v < FAN_LEVELS - 1) ? FAN_LEVELS - 1 : (int32_t)v;
        level_start[level[k] + 1]++;
    }
    for (int32_t v = 0; v < FAN_LEVELS; v++)
        level_start[v + 1] += level_start[v];
    for (int32_t k = 0; k < items; k++)
        order[level_start[level[k]]++] = k;
    /* each item's spans: the groups its angle from the turn's centre reaches, and in
     * each the bins of its angle from the group's centre */
    for (int32_t i = 0; i < items; i++) {
        int32_t k = order[i];
        int32_t q0 = 0, nq = FAN_GROUPS;
        if (hi[k] - lo[k] < 4.0) {
            int32_t f0 = floor_int(lo[k] * (FAN_GROUPS / 4.0)), f1 = floor_int(hi[k] * (FAN_GROUPS / 4.0));
            nq = f1 - f0 + 1;
            nq = nq > FAN_GROUPS ? FAN_GROUPS : nq;
            q0 = ((f0 % FAN_GROUPS) + FAN_GROUPS) % FAN_GROUPS;
        }
        for (int32_t m = 0, q = q0; m < nq; m++, q = q + 1 == FAN_GROUPS ? 0 : q + 1) {
            if (!used[q])
                continue;
            double glo, ghi, near;
            item_extent(g, k, gcx[q], gcy[q], grad[q], margin, &glo, &ghi, &near);
            int32_t first = q * per_group, last = first + per_group - 1;
            if (!(ghi - glo < 4.0)) {
                if (!spans_add(&spans, k, first, last, near))
                    goto fail;
                continue;
            }
            /* the bins glo .. ghi, unwrapped, met with the group's bins a turn apart */
            int32_t bl = floor_int(glo * per_unit), bh = floor_int(ghi * per_unit);
            int32_t turn = bl >= 0 ? bl / bins : -((-bl + bins - 1) / bins);
            for (; turn * bins <= bh; turn++) {
                int32_t a = bl > first + turn * bins ? bl : first + turn * bins;
                int32_t b = bh < last + turn * bins ? bh : last + turn * bins;
                if (a <= b && !spans_add(&spans, k, a - turn * bins, b - turn * bins, near))
                    goto fail;
            }
        }
    }
    /* the entries, counted first (as many as FAN_MAX_ENTRIES: else the walk) */
    size_t entries = 0;
    for (size_t s = 0; s < spans.n; s++)
        entries += (size_t)(spans.at[s].hi - spans.at[s].lo + 1);
    if (entries > FAN_MAX_ENTRIES)
        goto fail;
    for (size_t s = 0; s < spans.n; s++)
        for (int32_t b = spans.at[s].lo; b <= spans.at[s].hi; b++)
            w->start[b + 1]++;
    for (int32_t b = 0; b < bins; b++)
        w->start[b + 1] += w->start[b];
    w->entry = malloc(sizeof(int32_t) * (entries ? entries : 1));
    w->bound = malloc(sizeof(double) * (entries ? entries : 1));
    if (!w->entry || !w->bound)
        goto fail;
    int32_t *cursor = w->bin + samples;     /* the workspace's room for it (rays_open) */
    for (int32_t b = 0; b < bins; b++)
        cursor[b] = w->start[b];
    for (size_t s = 0; s < spans.n; s++) {
        const fan_span *p = spans.at + s;
        for (int32_t b = p->lo; b <= p->hi; b++) {
            w->entry[cursor[b]] = p->item;
            w->bound[cursor[b]++] = p->near;
        }
    }
    /* each entry's bound: the least near of it and every later entry in its bin */
    for (int32_t b = 0; b < bins; b++) {
        double least = INFINITY;
        for (int32_t i = w->start[b + 1] - 1; i >= w->start[b]; i--) {
            least = min2(least, w->bound[i]);
            w->bound[i] = least;
        }
    }
    free(spans.at);
    free(level);
    free(lo);
    return 1;
fail:
    free(spans.at);
    free(level);
    free(lo);
    free(w->start);
    free(w->entry);
    free(w->bound);
    w->start = 0; w->entry = 0; w->bound = 0;
    return 0;
}

/* ray j's figure: cast_one's (max_range inf), from the fan where the ray has a bin */
static double rays_cast(const rc_rays *w, const rc_grid *g, int32_t j) {
    double ox = w->ox[j], oy = w->oy[j], dx = w->dx[j], dy = w->dy[j];
    int32_t b = w->start ? w->bin[j] : -1;
    if (b < 0)
        return cast_one(g, ox, oy, dx, dy, INFINITY);
    double best = INFINITY;
    const double *rec = g->item_rec;
    for (int32_t i = w->start[b], end = w->start[b + 1]; i < end; i++) {
        if (best < w->bound[i])
            break;
        int32_t k = w->entry[i];
        best = k < g->n_seg ? meet_segment(rec + 4 * (ptrdiff_t)k, ox, oy, dx, dy, best)
                            : meet_circle(rec + 4 * (ptrdiff_t)k, ox, oy, dx, dy, best);
    }
    return best + 0.0;
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
static void turn_rays(const rc_lidar *L, double t0, int32_t n, const double *kt, const double *kx,
                      const double *ky, const double *kh, int32_t j0, int32_t j1, double *rox, double *roy,
                      double *rdx, double *rdy) {
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
        rox[j - j0] = ox;
        roy[j - j0] = oy;
        rdx[j - j0] = c * d[0] - s * d[1];
        rdy[j - j0] = s * d[0] + c * d[1];
    }
}

/* sample j's quarter millimetres from its ray's figure r: its noise added
 * (noise[j] * sigma, none without `noise`), to the nearest quarter millimetre, ties to
 * even (2^52 added and taken off: the default rounding, for 0 <= r * 4000 < 2^51), 0
 * below device_min or above range_max */
static inline int32_t quarter_mm(const rc_lidar *L, const double *noise, int32_t j, double r) {
    if (noise)
        r = r + (0.0 + L->sigma * noise[j]);
    return isfinite(r) && r >= L->device_min && r <= L->range_max
           ? (int32_t)((r * 4000.0 + 0x1p52) - 0x1p52) : 0;
}

/* A turn's rays in a workspace of its own (NULL when it cannot be had), with room
 * for a fan of `bins` bins (0: none) */
static rc_rays *rays_open(int32_t samples, int32_t bins) {
    rc_rays *w = calloc(1, sizeof *w);
    if (!w)
        return 0;
    w->ox = malloc(sizeof(double) * 4 * (size_t)(samples > 0 ? samples : 1));
    w->bin = malloc(sizeof(int32_t) * ((size_t)samples + (size_t)bins + 1));
    if (!w->ox || !w->bin) {
        free(w->ox);
        free(w->bin);
        free(w);
        return 0;
    }
    w->oy = w->ox + samples;
    w->dx = w->oy + samples;
    w->dy = w->dx + samples;
    w->bins = bins;
    return w;
}

static void rays_close(rc_rays *w) {
    if (!w)
        return;
    free(w->ox);
    free(w->bin);
    free(w->start);
    free(w->entry);
    free(w->bound);
    free(w);
}

/* The turn's rays and fan: a workspace, NULL when none could be had. */
static rc_rays *rays_make(const rc_grid *g, const rc_lidar *L, double t0, int32_t n, const double *kt,
                          const double *kx, const double *ky, const double *kh) {
    int32_t items = g->n_seg + g->n_circ;
    int32_t bins = g->item_rec && g->fan_bins >= FAN_GROUPS && items <= FAN_ITEMS_PER_SAMPLE * L->samples
                   ? g->fan_bins / FAN_GROUPS * FAN_GROUPS : 0;
    rc_rays *w = rays_open(L->samples, bins);
    if (!w)
        return 0;
    turn_rays(L, t0, n, kt, kx, ky, kh, 0, L->samples, w->ox, w->oy, w->dx, w->dy);
    if (bins && !fan_build(w, g, L->samples))
        w->bins = 0;
    return w;
}

/* samples j0 .. j1 - 1 into q2: from the rays in w, or without w, each pose made and
 * its ray walked a few at a time */
static void scan_samples(const rc_grid *g, const rc_rays *w, const rc_lidar *L, double t0, int32_t n,
                         const double *kt, const double *kx, const double *ky, const double *kh,
                         const double *noise, int32_t j0, int32_t j1, int32_t *q2) {
    if (w) {
        for (int32_t j = j0; j < j1; j++)
            q2[j] = quarter_mm(L, noise, j, rays_cast(w, g, j));
        return;
    }
    enum { FEW = 64 };
    double ox[FEW], oy[FEW], dx[FEW], dy[FEW];
    for (int32_t a = j0; a < j1; a += FEW) {
        int32_t b = a + FEW < j1 ? a + FEW : j1;
        turn_rays(L, t0, n, kt, kx, ky, kh, a, b, ox, oy, dx, dy);
        for (int32_t j = a; j < b; j++)
            q2[j] = quarter_mm(L, noise, j, cast_one(g, ox[j - a], oy[j - a], dx[j - a], dy[j - a], INFINITY));
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
    rc_rays *w = rays_make(g, L, t0, n, kt, kx, ky, kh);
    scan_samples(g, w, L, t0, n, kt, kx, ky, kh, noise, 0, L->samples, q2);
    rays_close(w);
    bin_samples(L, t0, q2, ranges, intensities, beam_time);
}

/* One turn to make: its poses from knots kt, kx, ky, kh (n of them) or, with `log`,
 * from the motion log's rows integrated from (start_x, start_y, start_h) at log_t0
 * into them (n = log_rows + 1, the knots written); then rc_scan from t0 into q2 ..
 * beam_time.
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
    rc_rays *rays;          /* the turn's rays and fan while its chunks are made (NULL: none) */
    /* with `bitgen` (a numpy bit generator, where rc_draws() is 1), the job draws its
     * noise into `draws` (samples) first: its standard normal draws, in the order the
     * jobs were submitted; `noise` is then `draws` */
    void *bitgen;
    double *draws;
    double log_t0;          /* the time of the motion log's start pose */
} rc_job;

/* 1 where jobs can draw their noise (numpy's generator linked in) */
int32_t rc_draws(void) {
#ifdef WC_NPYRANDOM
    return 1;
#else
    return 0;
#endif
}

static void draw_job(rc_job *job) {
#ifdef WC_NPYRANDOM
    if (job->bitgen && job->draws) {
        for (int32_t j = 0; j < job->lidar->samples; j++)
            job->draws[j] = random_standard_normal((bitgen_t *)job->bitgen);
        job->noise = job->draws;
    }
#else
    (void)job;
#endif
}

enum { JOB_QUEUED, JOB_STARTING, JOB_CHUNKS, JOB_DONE };
/* samples in a chunk: a few tens of microseconds of work */
#define CHUNK 256

static void integrate_job(rc_job *job) {
    if (job->log)
        rc_integrate(job->log_t0, job->start_x, job->start_y, job->start_h, job->log_rows, job->log,
                     job->log_stride, job->kt, job->kx, job->ky, job->kh);
}

static void scan_chunk(rc_job *job, int32_t chunk) {
    int32_t j0 = chunk * CHUNK, j1 = j0 + CHUNK < job->lidar->samples ? j0 + CHUNK : job->lidar->samples;
    scan_samples(job->grid, job->rays, job->lidar, job->t0, job->n, job->kt, job->kx, job->ky, job->kh,
                 job->noise, j0, j1, job->q2);
}

/* the job's rays and fan (once its poses' knots are integrated) */
static void rays_job(rc_job *job) {
    job->rays = rays_make(job->grid, job->lidar, job->t0, job->n, job->kt, job->kx, job->ky, job->kh);
}

static void bin_job(rc_job *job) {
    rays_close(job->rays);
    job->rays = 0;
    bin_samples(job->lidar, job->t0, job->q2, job->ranges, job->intensities, job->beam_time);
}

void rc_run(rc_job *job) {
    draw_job(job);
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
    pthread_mutex_t draw_lock;  /* held while a job draws: jobs start, and draw, in order */
    pthread_cond_t work, finished;
    rc_job *head, *tail;
    int closing;
    int32_t queued;         /* jobs queued: read without the lock by the idle thread */
    int64_t idle_ns;        /* how long the thread was last idle before a job came */
} rc_pipe;

/* ns: how long the idle thread watches for a job before it sleeps. Waking a sleeping
 * thread costs the submitter 15 to 20 us on this project's machine (a virtual one);
 * turns that follow each other within it find the thread awake. It watches only
 * while jobs have come within that time: where they come further apart (a slower
 * caller, say one that shares its core with other work), watching would only take a
 * core from the rest, and the thread sleeps at once. */
#ifndef PIPE_AWAKE_NS
#define PIPE_AWAKE_NS 100000
#endif

static int64_t monotonic_ns(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (int64_t)t.tv_sec * 1000000000 + t.tv_nsec;
}

/* With the lock held (and held again on return): waits awake up to PIPE_AWAKE_NS for
 * a job to be queued, or the pipe closed. */
static void stay_awake(rc_pipe *p) {
    pthread_mutex_unlock(&p->lock);
    int64_t until = monotonic_ns() + PIPE_AWAKE_NS;
    while (!__atomic_load_n(&p->queued, __ATOMIC_ACQUIRE) && !__atomic_load_n(&p->closing, __ATOMIC_ACQUIRE)) {
        for (int i = 0; i < 64; i++) {
#if defined(__x86_64__) || defined(__i386__)
            __builtin_ia32_pause();
#endif
        }
        if (monotonic_ns() > until)
            break;
    }
    pthread_mutex_lock(&p->lock);
}

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

/* With the lock held: takes the queue's first job out of it, draws its noise,
 * integrates its poses, makes its rays and fan and opens its chunks. */
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
        __atomic_store_n(&p->queued, p->queued - 1, __ATOMIC_RELEASE);
    }
    job->state = JOB_STARTING;
    /* the draws in the order the jobs started (a later start waits here, the lock held) */
    pthread_mutex_lock(&p->draw_lock);
    pthread_mutex_unlock(&p->lock);
    draw_job(job);
    pthread_mutex_unlock(&p->draw_lock);
    integrate_job(job);
    rays_job(job);
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
        if (!p->head && !p->closing) {
            int64_t idle = monotonic_ns();
            if (p->idle_ns <= PIPE_AWAKE_NS)
                stay_awake(p);
            while (!p->head && !p->closing)
                pthread_cond_wait(&p->work, &p->lock);
            p->idle_ns = monotonic_ns() - idle;
        }
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
    if (pthread_mutex_init(&p->draw_lock, 0) != 0) {
        pthread_mutex_destroy(&p->lock);
        free(p);
        return 0;
    }
    if (pthread_cond_init(&p->work, 0) != 0 || pthread_cond_init(&p->finished, 0) != 0
            || pthread_create(&p->thread, 0, pipe_main, p) != 0) {
        /* the conditions need no destroying here: neither was waited on */
        pthread_mutex_destroy(&p->draw_lock);
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
    __atomic_store_n(&p->queued, p->queued + 1, __ATOMIC_RELEASE);
    pthread_cond_signal(&p->work);
    pthread_mutex_unlock(&p->lock);
}

/* Returns once the job is done, making what is left of it meanwhile. */
void rc_pipe_wait(rc_pipe *p, rc_job *job) {
    pthread_mutex_lock(&p->lock);
    while (job->state != JOB_DONE) {
        if (job->state == JOB_QUEUED) {
            /* the jobs start in order: those queued before it first */
            rc_job *first = p->head;
            start_job(p, first);
            if (first != job) {
                make_chunks(p, first);
                continue;
            }
        }
        make_chunks(p, job);
        if (job->state != JOB_DONE)
            pthread_cond_wait(&p->finished, &p->lock);
    }
    pthread_mutex_unlock(&p->lock);
}

/* Runs the jobs still queued, stops the thread and frees the pipe. */
void rc_pipe_close(rc_pipe *p) {
    pthread_mutex_lock(&p->lock);
    __atomic_store_n(&p->closing, 1, __ATOMIC_RELEASE);
    pthread_cond_signal(&p->work);
    pthread_mutex_unlock(&p->lock);
    pthread_join(p->thread, 0);
    pthread_cond_destroy(&p->work);
    pthread_cond_destroy(&p->finished);
    pthread_mutex_destroy(&p->draw_lock);
    pthread_mutex_destroy(&p->lock);
    free(p);
}

/* The layouts of rc_grid, rc_lidar and rc_job as compiled, for the check that their
 * ctypes mirrors (wcdrive.plant.raycast's GridStruct, TurnStruct and JobStruct) lay
 * them out alike (wcdrive.plant.struct_layout, whose docstring describes these
 * records): each field's name, offset, size and kind, from offsetof, sizeof and
 * _Generic. A field added to one of the structs is added here too: the check refuses
 * a mirror with a field a table lacks, and a table with a gap wider than alignment
 * explains. */
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
#define WC_LAYOUT(T, fields) { sizeof(wc_layout), sizeof(wc_field), #T, sizeof(T), \
                               sizeof fields / sizeof fields[0], fields }

#define F(f) WC_FIELD(rc_grid, f)
static const wc_field grid_fields[] = {
    F(seg), F(n_seg), F(circ), F(n_circ), F(minx), F(miny), F(cs), F(inv_cs), F(nx), F(ny), F(eps),
    F(start), F(items), F(rec), F(seg_end), F(item_rec), F(fan_bins), F(scale),
};
#undef F
#define F(f) WC_FIELD(rc_lidar, f)
static const wc_field lidar_fields[] = {
    F(samples), F(offset), F(device), F(first_bin), F(beams), F(multiple), F(mount_x), F(mount_y),
    F(sigma), F(device_min), F(range_max), F(intensity), F(reverse),
};
#undef F
#define F(f) WC_FIELD(rc_job, f)
static const wc_field job_fields[] = {
    F(grid), F(lidar), F(t0), F(n), F(kt), F(kx), F(ky), F(kh), F(log), F(log_rows), F(log_stride),
    F(start_x), F(start_y), F(start_h), F(noise), F(q2), F(ranges), F(intensities), F(beam_time),
    F(state), F(next_chunk), F(chunks_left), F(next), F(rays), F(bitgen), F(draws), F(log_t0),
};
#undef F

static const wc_layout grid_layout = WC_LAYOUT(rc_grid, grid_fields);
static const wc_layout lidar_layout = WC_LAYOUT(rc_lidar, lidar_fields);
static const wc_layout job_layout = WC_LAYOUT(rc_job, job_fields);

const wc_layout *rc_grid_layout(void) { return &grid_layout; }
const wc_layout *rc_lidar_layout(void) { return &lidar_layout; }
const wc_layout *rc_job_layout(void) { return &job_layout; }
