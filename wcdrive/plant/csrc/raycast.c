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
 * cell (ix, iy) is c = iy * nx + ix and holds items[start[c] .. start[c + 1]).
 */
#include <math.h>
#include <stdint.h>

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
        int ix0 = clamp_cell(floor((lox - g->eps - g->minx) * g->inv_cs), g->nx);
        int ix1 = clamp_cell(floor((hix + g->eps - g->minx) * g->inv_cs), g->nx);
        int iy0 = clamp_cell(floor((loy - g->eps - g->miny) * g->inv_cs), g->ny);
        int iy1 = clamp_cell(floor((hiy + g->eps - g->miny) * g->inv_cs), g->ny);
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
    double inv_dx = sx ? 1.0 / dx : 0.0, inv_dy = sy ? 1.0 / dy : 0.0;
    /* the part of the ray inside the grid */
    double t0 = 0.0, t1 = INFINITY;
    if (sx) {
        double a = (minx - ox) * inv_dx, b = (maxx - ox) * inv_dx;
        t0 = fmax(t0, fmin(a, b));
        t1 = fmin(t1, fmax(a, b));
    } else if (ox < minx || ox > maxx) {
        return INFINITY;
    }
    if (sy) {
        double a = (miny - oy) * inv_dy, b = (maxy - oy) * inv_dy;
        t0 = fmax(t0, fmin(a, b));
        t1 = fmin(t1, fmax(a, b));
    } else if (oy < miny || oy > maxy) {
        return INFINITY;
    }
    /* beyond `limit` no hit can be within max_range */
    double limit = max_range + g->eps + 1e-12 * fabs(max_range);
    if (t0 > t1 || t0 > limit)
        return INFINITY;
    int ix = clamp_cell(floor((ox + t0 * dx - minx) * g->inv_cs), g->nx);
    int iy = clamp_cell(floor((oy + t0 * dy - miny) * g->inv_cs), g->ny);
    double best = INFINITY;
    /* where the ray leaves the first cell across x and across y, and how far on it
     * crosses the next column and row: the sums round, far below eps */
    double tx = sx > 0 ? (minx + (ix + 1) * cs - ox) * inv_dx
              : sx < 0 ? (minx + ix * cs - ox) * inv_dx : INFINITY;
    double ty = sy > 0 ? (miny + (iy + 1) * cs - oy) * inv_dy
              : sy < 0 ? (miny + iy * cs - oy) * inv_dy : INFINITY;
    const double step_x = sx ? cs * fabs(inv_dx) : INFINITY, step_y = sy ? cs * fabs(inv_dy) : INFINITY;
    for (;;) {
        double texit = fmin(tx, ty);
        int32_t c = iy * g->nx + ix;
        for (int32_t i = g->start[c], end = g->start[c + 1]; i < end; i++) {
            int32_t k = g->items[i];
            if (k < g->n_seg) {
                const double *s = g->seg + 4 * k;
                double x0 = s[0], y0 = s[1];
                double ex = s[2] - x0, ey = s[3] - y0;
                double denom = dx * ey - dy * ex;
                if (denom == 0.0)
                    continue;
                double wx = x0 - ox, wy = y0 - oy;
                double t = (wx * ey - wy * ex) / denom;
                double u = (wx * dy - wy * dx) / denom;
                if (t >= 0.0 && u >= 0.0 && u <= 1.0 && t < best)
                    best = t;
            } else {
                const double *q = g->circ + 3 * (k - g->n_seg);
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
        }
        if (best <= texit || texit > limit)
            break;
        if (tx < ty) {
            ix += sx;
            if (ix < 0 || ix >= g->nx) break;
            tx += step_x;
        } else {
            iy += sy;
            if (iy < 0 || iy >= g->ny) break;
            ty += step_y;
        }
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
