#include <math.h>
#include <stdlib.h>
#include <string.h>
/* Plain compiled loops for the reference-field kernel (orbitcal.field._kernel), called by
   benchmarks/truth_field.py --kernel-only through ctypes.

   synth_lanes: the same algorithm as the kernel. For each order m the degree recursion of the
   Schmidt functions keeps its two previous terms in registers and each term is summed at once;
   samples that share a model piece are taken LANES at a time (loops over lanes vectorise; for a
   model linear in time, one loop per (n, m) with (a/r)^(n+2) carried by the Legendre functions),
   the others one at a time. Coefficients in the kernel's order-major layout (P, K, order).

   synth_rows: the previous algorithm (per sample: Horner for all coefficients into a buffer,
   P and dP/dtheta stored row by row, then summed per degree). Degree-block layout (order, P, K). */

#define LANES 32
enum { X, S, CP, SP, CM, SM, PMM, DPMM, P1, P2, DP1, DP2, BR, BT, BP, D, AR, RM, RN, G, H, XA, SA, AR2, NROWS };

static void sample(const double *restrict ppm, int order, int K, long j, double d, double radius,
                   double colat, double lon, int nmin, int nmax, const double *restrict ab,
                   const double *restrict d_c, double *restrict out) {
  double th = colat < 1e-9 ? 1e-9 : colat;
  if (th > M_PI - 1e-9) th = M_PI - 1e-9;
  double x = cos(th), s = sin(th), cp = cos(lon), sp = sin(lon);
  double ar = 6371.2 / radius, r_m = ar * ar, cm = 1, sm = 0, pmm = 1, dpmm = 0;
  double br = 0, bt = 0, bp = 0;
  const double *c = ppm + j * K * order;
  int k = 0, q = 0;
  for (int m = 0; m <= nmax; m++) {
    double fm = m;
    if (m >= 1) {
      double dm = d_c[m];
      dpmm = dm * (s * dpmm + x * pmm);
      pmm = dm * s * pmm;
      double cm2 = cm * cp - sm * sp;
      sm = sm * cp + cm * sp;
      cm = cm2;
      r_m *= ar;
      if (m >= nmin) {
        double g = 0, h = 0;
        for (int o = 0; o < order; o++) { g = g * d + c[k * order + o]; h = h * d + c[(k + 1) * order + o]; }
        double t1 = g * cm + h * sm, t2 = fm * (h * cm - g * sm);
        br += (m + 1) * r_m * pmm * t1; bt -= r_m * dpmm * t1; bp -= r_m * pmm * t2;
      }
      k += 2;
    }
    double p1 = pmm, dp1 = dpmm, p2 = 0, dp2 = 0, r_n = r_m;
    for (int n = m + 1; n <= nmax; n++) {
      double a = ab[2 * q], bb = ab[2 * q + 1];
      q++;
      double p = a * x * p1 - bb * p2, dp = a * (x * dp1 - s * p1) - bb * dp2;
      p2 = p1; p1 = p; dp2 = dp1; dp1 = dp;
      r_n *= ar;
      if (n >= nmin) {
        double g = 0, h = 0;
        for (int o = 0; o < order; o++) { g = g * d + c[k * order + o]; h = h * d + c[(k + 1) * order + o]; }
        double t1 = g * cm + h * sm, t2 = fm * (h * cm - g * sm);
        br += (n + 1) * r_n * p * t1; bt -= r_n * dp * t1; bp -= r_n * p * t2;
      }
      k += 2;
    }
  }
  out[0] += -bt; out[1] += bp / s; out[2] += -br;
}

static void block(const double *restrict ppm, int order, int K, long j, const double *restrict dt,
                  const double *restrict radius, const double *restrict colat,
                  const double *restrict lon, int nmin, int nmax, const double *restrict ab,
                  const double *restrict d_c, double *restrict out) {
  double v[NROWS][LANES];
  const double *c = ppm + j * K * order;
  for (int b = 0; b < LANES; b++) {
    double th = colat[b] < 1e-9 ? 1e-9 : colat[b];
    if (th > M_PI - 1e-9) th = M_PI - 1e-9;
    v[D][b] = dt[b]; v[X][b] = cos(th); v[S][b] = sin(th); v[CP][b] = cos(lon[b]); v[SP][b] = sin(lon[b]);
    double ar = 6371.2 / radius[b];
    v[AR][b] = ar; v[RM][b] = ar * ar; v[CM][b] = 1; v[SM][b] = 0; v[PMM][b] = 1; v[DPMM][b] = 0;
    v[BR][b] = 0; v[BT][b] = 0; v[BP][b] = 0;
  }
  int k = 0, q = 0;
  for (int m = 0; m <= nmax; m++) {
    double fm = m;
    if (m >= 1) {
      double dm = d_c[m];
      for (int b = 0; b < LANES; b++) {
        double x = v[X][b], s = v[S][b], pmm = v[PMM][b], cm = v[CM][b], sm = v[SM][b];
        v[DPMM][b] = dm * (s * v[DPMM][b] + x * pmm);
        v[PMM][b] = dm * s * pmm;
        v[CM][b] = cm * v[CP][b] - sm * v[SP][b];
        v[SM][b] = sm * v[CP][b] + cm * v[SP][b];
        v[RM][b] *= v[AR][b];
      }
      if (m >= nmin) {
        for (int b = 0; b < LANES; b++) { v[G][b] = 0; v[H][b] = 0; }
        for (int o = 0; o < order; o++) {
          double cg = c[k * order + o], ch = c[(k + 1) * order + o];
          for (int b = 0; b < LANES; b++) { v[G][b] = v[G][b] * v[D][b] + cg; v[H][b] = v[H][b] * v[D][b] + ch; }
        }
        double f1 = m + 1;
        for (int b = 0; b < LANES; b++) {
          double g = v[G][b], h = v[H][b], cm = v[CM][b], sm = v[SM][b];
          double t1 = g * cm + h * sm, t2 = fm * (h * cm - g * sm), rn = v[RM][b], p = v[PMM][b];
          v[BR][b] += f1 * rn * p * t1; v[BT][b] -= rn * v[DPMM][b] * t1; v[BP][b] -= rn * p * t2;
        }
      }
      k += 2;
    }
    for (int b = 0; b < LANES; b++) {
      v[P1][b] = v[PMM][b]; v[DP1][b] = v[DPMM][b]; v[P2][b] = 0; v[DP2][b] = 0; v[RN][b] = v[RM][b];
    }
    for (int n = m + 1; n <= nmax; n++) {
      double a = ab[2 * q], bb = ab[2 * q + 1];
      q++;
      for (int b = 0; b < LANES; b++) {
        double x = v[X][b], p1 = v[P1][b], dp1 = v[DP1][b];
        double p = a * x * p1 - bb * v[P2][b];
        double dp = a * (x * dp1 - v[S][b] * p1) - bb * v[DP2][b];
        v[P2][b] = p1; v[P1][b] = p; v[DP2][b] = dp1; v[DP1][b] = dp;
        v[RN][b] *= v[AR][b];
      }
      if (n >= nmin) {
        for (int b = 0; b < LANES; b++) { v[G][b] = 0; v[H][b] = 0; }
        for (int o = 0; o < order; o++) {
          double cg = c[k * order + o], ch = c[(k + 1) * order + o];
          for (int b = 0; b < LANES; b++) { v[G][b] = v[G][b] * v[D][b] + cg; v[H][b] = v[H][b] * v[D][b] + ch; }
        }
        double f1 = n + 1;
        for (int b = 0; b < LANES; b++) {
          double g = v[G][b], h = v[H][b], cm = v[CM][b], sm = v[SM][b];
          double t1 = g * cm + h * sm, t2 = fm * (h * cm - g * sm), rn = v[RN][b], p = v[P1][b];
          v[BR][b] += f1 * rn * p * t1; v[BT][b] -= rn * v[DP1][b] * t1; v[BP][b] -= rn * p * t2;
        }
      }
      k += 2;
    }
  }
  for (int b = 0; b < LANES; b++) {
    out[3 * b] += -v[BT][b]; out[3 * b + 1] += v[BP][b] / v[S][b]; out[3 * b + 2] += -v[BR][b];
  }
}

/* Order 2 (linear in time within a piece): one loop over lanes per (n, m) for the recursion, the
   coefficients and the sums; the Legendre functions carry (a/r)^(n+2). */
static void block_linear(const double *restrict ppm, int K, long j, const double *restrict dt,
                         const double *restrict radius, const double *restrict colat,
                         const double *restrict lon, int nmin, int nmax, const double *restrict ab,
                         const double *restrict d_c, double *restrict out) {
  double v[NROWS][LANES];
  const double *c = ppm + j * K * 2;
  for (int b = 0; b < LANES; b++) {
    double th = colat[b] < 1e-9 ? 1e-9 : colat[b];
    if (th > M_PI - 1e-9) th = M_PI - 1e-9;
    double ar = 6371.2 / radius[b], s = sin(th);
    v[D][b] = dt[b]; v[S][b] = s; v[XA][b] = cos(th) * ar; v[SA][b] = s * ar; v[AR2][b] = ar * ar;
    v[CP][b] = cos(lon[b]); v[SP][b] = sin(lon[b]); v[CM][b] = 1; v[SM][b] = 0;
    v[PMM][b] = ar * ar; v[DPMM][b] = 0; v[BR][b] = 0; v[BT][b] = 0; v[BP][b] = 0;
  }
  int k = 0, q = 0;
  for (int m = 0; m <= nmax; m++) {
    double fm = m;
    if (m >= 1) {
      double dm = d_c[m], use = m >= nmin ? 1.0 : 0.0, f1 = m + 1;
      double g0 = c[2 * k] * use, g1 = c[2 * k + 1] * use, h0 = c[2 * k + 2] * use, h1 = c[2 * k + 3] * use;
      for (int b = 0; b < LANES; b++) {
        double xa = v[XA][b], sa = v[SA][b], pmm = v[PMM][b];
        double dpmm = dm * (sa * v[DPMM][b] + xa * pmm);
        pmm = dm * sa * pmm;
        v[DPMM][b] = dpmm; v[PMM][b] = pmm;
        double cm0 = v[CM][b], sm0 = v[SM][b];
        double cm = cm0 * v[CP][b] - sm0 * v[SP][b], sm = sm0 * v[CP][b] + cm0 * v[SP][b];
        v[CM][b] = cm; v[SM][b] = sm;
        double g = g0 * v[D][b] + g1, h = h0 * v[D][b] + h1;
        double t1 = g * cm + h * sm, t2 = fm * (h * cm - g * sm);
        v[BR][b] += f1 * pmm * t1; v[BT][b] -= dpmm * t1; v[BP][b] -= pmm * t2;
      }
      k += 2;
    }
    for (int b = 0; b < LANES; b++) { v[P1][b] = v[PMM][b]; v[DP1][b] = v[DPMM][b]; v[P2][b] = 0; v[DP2][b] = 0; }
    for (int n = m + 1; n <= nmax; n++) {
      double a = ab[2 * q], bb = ab[2 * q + 1], use = n >= nmin ? 1.0 : 0.0, f1 = n + 1;
      q++;
      double g0 = c[2 * k] * use, g1 = c[2 * k + 1] * use, h0 = c[2 * k + 2] * use, h1 = c[2 * k + 3] * use;
      for (int b = 0; b < LANES; b++) {
        double xa = v[XA][b], p1 = v[P1][b], dp1 = v[DP1][b], bb_ar2 = bb * v[AR2][b];
        double p = a * xa * p1 - bb_ar2 * v[P2][b];
        double dp = a * (xa * dp1 - v[SA][b] * p1) - bb_ar2 * v[DP2][b];
        v[P2][b] = p1; v[P1][b] = p; v[DP2][b] = dp1; v[DP1][b] = dp;
        double g = g0 * v[D][b] + g1, h = h0 * v[D][b] + h1, cm = v[CM][b], sm = v[SM][b];
        double t1 = g * cm + h * sm, t2 = fm * (h * cm - g * sm);
        v[BR][b] += f1 * p * t1; v[BT][b] -= dp * t1; v[BP][b] -= p * t2;
      }
      k += 2;
    }
  }
  for (int b = 0; b < LANES; b++) {
    out[3 * b] += -v[BT][b]; out[3 * b + 1] += v[BP][b] / v[S][b]; out[3 * b + 2] += -v[BR][b];
  }
}

void synth_lanes(const double *ppm, int order, int K, const long *piece, const double *dt,
                 const double *radius, const double *colat, const double *lon, int nmin, int nmax,
                 const double *ab, const double *d_c, long start, long stop, double *out) {
  long i0 = start;
  for (; i0 + LANES <= stop; i0 += LANES) {
    long j = piece[i0];
    int same = 1;
    for (long i = i0 + 1; i < i0 + LANES; i++) same &= piece[i] == j;
    if (same && order == 2)
      block_linear(ppm, K, j, dt + i0, radius + i0, colat + i0, lon + i0, nmin, nmax, ab, d_c, out + 3 * i0);
    else if (same)
      block(ppm, order, K, j, dt + i0, radius + i0, colat + i0, lon + i0, nmin, nmax, ab, d_c, out + 3 * i0);
    else
      for (long i = i0; i < i0 + LANES; i++)
        sample(ppm, order, K, piece[i], dt[i], radius[i], colat[i], lon[i], nmin, nmax, ab, d_c, out + 3 * i);
  }
  for (long i = i0; i < stop; i++)
    sample(ppm, order, K, piece[i], dt[i], radius[i], colat[i], lon[i], nmin, nmax, ab, d_c, out + 3 * i);
}

void synth_rows(const double *pp, int order, int npieces, int K, const long *piece, const double *dt,
                const double *radius, const double *colat, const double *lon, int nmin, int nmax,
                long start, long stop, double *out) {
  int W = nmax + 2;
  double *a_c = calloc((nmax + 1) * W, 8), *b_c = calloc((nmax + 1) * W, 8), *d_c = malloc((nmax + 1) * 8);
  double *pnm = calloc((nmax + 1) * W, 8), *dpnm = calloc((nmax + 1) * W, 8);
  double *cosm = calloc(nmax + 1, 8), *sinm = calloc(nmax + 1, 8), *coef = calloc(K, 8);
  for (int n = 0; n <= nmax; n++) d_c[n] = 1.0;
  for (int n = 1; n <= nmax; n++) {
    for (int m = 0; m < n; m++) {
      double den = sqrt((double)(n * n - m * m));
      a_c[n * W + m] = (2 * n - 1) / den;
      if ((n - 1) * (n - 1) > m * m) b_c[n * W + m] = sqrt((double)((n - 1) * (n - 1) - m * m)) / den;
    }
    if (n >= 2) d_c[n] = sqrt((2.0 * n - 1) / (2.0 * n));
  }
  for (long i = start; i < stop; i++) {
    long j = piece[i]; double d = dt[i];
    for (int k = 0; k < K; k++) {
      double c = pp[(0 * npieces + j) * K + k];
      for (int o = 1; o < order; o++) c = c * d + pp[((long)o * npieces + j) * K + k];
      coef[k] = c;
    }
    double th = colat[i]; if (th < 1e-9) th = 1e-9; if (th > M_PI - 1e-9) th = M_PI - 1e-9;
    double x = cos(th), s = sin(th), cp = cos(lon[i]), sp = sin(lon[i]);
    cosm[0] = 1; sinm[0] = 0;
    for (int m = 1; m <= nmax; m++) { cosm[m] = cosm[m-1]*cp - sinm[m-1]*sp; sinm[m] = sinm[m-1]*cp + cosm[m-1]*sp; }
    double ar = 6371.2 / radius[i], rr = ar * ar;
    pnm[0] = 1; pnm[1] = 0; dpnm[0] = 0; dpnm[1] = 0;
    double br = 0, bt = 0, bp = 0; int off = 0;
    for (int n = 1; n <= nmax; n++) {
      double *P = pnm + n * W, *P1 = pnm + (n-1) * W, *dP = dpnm + n * W, *dP1 = dpnm + (n-1) * W;
      if (n == 1) { P[0] = x; dP[0] = -s; }
      else {
        double *P2 = pnm + (n-2) * W, *dP2 = dpnm + (n-2) * W;
        for (int m = 0; m < n; m++) {
          P[m] = a_c[n*W+m] * x * P1[m] - b_c[n*W+m] * P2[m];
          dP[m] = a_c[n*W+m] * (x * dP1[m] - s * P1[m]) - b_c[n*W+m] * dP2[m];
        }
      }
      P[n] = d_c[n] * s * P1[n-1]; dP[n] = d_c[n] * (s * dP1[n-1] + x * P1[n-1]);
      P[n+1] = 0; dP[n+1] = 0;
      rr *= ar;
      if (n >= nmin) {
        double sr = 0, st = 0, sph = 0;
        for (int m = 0; m <= n; m++) {
          double g = coef[off + m], h = coef[off + n + 1 + m];
          double t1 = g * cosm[m] + h * sinm[m], t2 = m * (h * cosm[m] - g * sinm[m]);
          sr += P[m] * t1; st += dP[m] * t1; sph += P[m] * t2;
        }
        br += (n + 1) * rr * sr; bt -= rr * st; bp -= rr * sph;
      }
      off += 2 * (n + 1);
    }
    out[i*3] += -bt; out[i*3+1] += bp / s; out[i*3+2] += -br;
  }
  free(a_c); free(b_c); free(d_c); free(pnm); free(dpnm); free(cosm); free(sinm); free(coef);
}
