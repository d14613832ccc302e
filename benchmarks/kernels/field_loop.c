#include <math.h>
#include <stdlib.h>
#include <string.h>
/* The same per-sample algorithm as orbitcal.field._kernel: Horner in time, Schmidt recursion. */
void synth(const double *pp, int order, int npieces, int K, const long *piece, const double *dt,
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
