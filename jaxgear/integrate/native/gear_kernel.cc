// Kink-aware RK4 for the reduced 2-DOF planetary gear model, as an XLA FFI custom call.
//
// The same arithmetic as jaxgear's pure-JAX path (jaxgear/integrate/_kink.py with the
// vector field of jaxgear/_model.py), written for the CPU: lanes in blocks of struct-of-
// arrays that stay in cache for all steps of a call, the time-only terms of the vector
// field (mesh stiffness, transmission errors) tabulated once per stage time, shared
// by every lane with the same parameters and kept for the next calls, the trial step vectorised over a block (several
// registers of lanes advanced together, the lanes with an event marked in bit masks), and
// the few lanes whose step holds a backlash crossing gathered and split together
// (vectorised over them; lane by lane for a known time break or a further event in the
// step). Blocks run in parallel (OpenMP).
//
// Built by jaxgear/integrate/_native.py on first use; the pure-JAX path stays the
// reference (for derivatives, GPUs, and machines without a C++ compiler).

// Floating-point exceptions are never read: comparisons under a branch may become selects
// (what lets the split loops vectorise); no result changes.
#pragma GCC optimize("no-trapping-math")

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <mutex>
#include <vector>

#include <omp.h>
#if defined(__AVX__) || defined(__AVX512F__)
#include <immintrin.h>
#endif

#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kBlock = 512;  // lanes per block
// The row stride of a block's arrays (4 x kBlock): not a multiple of 4 KiB, so that the rows
// of a block (the same lane in each row) do not alias in the processor's store-to-load checks.
constexpr int kRow = kBlock + 8;
constexpr int kMinBlock = 32;  // the shortest block a small pool is cut into
constexpr int kBlocksPerThread = 4;  // blocks per thread below kBlock lanes each (balance)
constexpr int kHermiteIters = 12;
constexpr double kEps = 2.220446049250313e-16;
constexpr double kBreakTol = 1e-10;  // BREAK_TOL of _kink.py
constexpr double kSimultaneous = 1e-12;  // SIMULTANEOUS of _kink.py

// Packed parameter row (the order of _native.PARAM_ORDER).
enum P {
  N_, MU_S, MU_P, MU_C, KSM, KSA, KRM, KRA, PHI_SP, PHI_RP, ESA, ERA, BETA_SP, BETA_RP,
  GAMMA_SR, B_SP, B_RP, C_SP, C_RP, F_D, F_L, OMEGA, CR_SP, CR_RP, NPARAM
};

struct Model {
  double p[NPARAM];
  int shape;  // 0 sine, 1 rectangular
  double T;
  double breaks[4];  // phases in [0, 1) of the rectangular wave's jumps
  int n_breaks;
};

struct Terms {  // time-only terms at one time
  double ksp, krp, E, dE, L1;
};

// A lane's parameter row as the pure-JAX path reads it (params[r]: a negative index counts
// from the end, and an index out of range is clamped to the nearest row): never out of bounds.
inline int row_index(int64_t r, int64_t rows) {
  if (r < 0) r += rows;
  return static_cast<int>(std::min<int64_t>(std::max<int64_t>(r, 0), rows - 1));
}

inline double floor_mod(double x, double m) { return x - m * std::floor(x / m); }

inline double wave(double angle, double cr, int shape) {
  if (shape == 0) return std::sin(angle);
  const double d = cr - 1.0;
  const double u = floor_mod(angle - 0.5 * kPi + kPi * d, 2.0 * kPi);
  const double dbl = u < 2.0 * kPi * d ? 1.0 : 0.0;
  return (kPi / (2.0 * std::sin(kPi * d))) * (dbl - d);
}

inline Terms terms(const Model& m, double t) {
  const double* p = m.p;
  const double W = p[OMEGA];
  Terms q;
  q.ksp = p[KSM] + p[KSA] * wave(W * t + p[PHI_SP], p[CR_SP], m.shape);
  q.krp = p[KRM] + p[KRA] * wave(W * t + p[PHI_RP], p[CR_RP], m.shape);
  const double a_sp = W * t + p[BETA_SP];
  const double a_rp = W * t + p[BETA_RP] + p[GAMMA_SR];
  const double s_sp = std::sin(a_sp), c_sp = std::cos(a_sp);
  const double e_sp = p[ESA] * s_sp;
  const double de_sp = p[ESA] * W * c_sp;
  const double dde_sp = -p[ESA] * W * W * s_sp;
  const double e_rp = p[ERA] * std::sin(a_rp);
  const double de_rp = p[ERA] * W * std::cos(a_rp);
  q.E = e_sp + e_rp;
  q.dE = de_sp + de_rp;
  q.L1 = p[MU_S] * p[F_D] + p[MU_C] * p[F_L] - dde_sp;
  return q;
}

// Time terms at an arbitrary time inside a step, without new trigonometric calls: the
// sines and cosines of the four phase angles at the step's start are tabulated, and the
// angle added since then, W (t - t_start) <= W h, is small (angle addition with short
// series, exact to round-off).
struct Clock {
  double t;         // step start
  double ang[4];    // W t + phi_sp, W t + phi_rp, W t + beta_sp, W t + beta_rp + gamma_sr
  double sn[4], cs[4];
};

// Time terms already computed during one lane's split (the same times recur: a sub-step's
// end is the next one's start, and the step's own stage times are tabulated).
struct TermCache {
  double t[12];
  Terms q[12];
  int n = 0;
};

inline Clock make_clock(const Model& m, double t) {
  const double* p = m.p;
  const double W = p[OMEGA];
  Clock c;
  c.t = t;
  c.ang[0] = W * t + p[PHI_SP];
  c.ang[1] = W * t + p[PHI_RP];
  c.ang[2] = W * t + p[BETA_SP];
  c.ang[3] = W * t + p[BETA_RP] + p[GAMMA_SR];
  for (int k = 0; k < 4; ++k) {
    c.sn[k] = std::sin(c.ang[k]);
    c.cs[k] = std::cos(c.ang[k]);
  }
  return c;
}

inline void small_sincos(double x, double* s, double* c) {
  if (std::fabs(x) > 0.2) {
    *s = std::sin(x);
    *c = std::cos(x);
    return;
  }
  const double x2 = x * x;
  *s = x * (1.0 + x2 * (-1.0 / 6 + x2 * (1.0 / 120 + x2 * (-1.0 / 5040 + x2 * (1.0 / 362880 + x2 * (-1.0 / 39916800))))));
  *c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24 + x2 * (-1.0 / 720 + x2 * (1.0 / 40320 + x2 * (-1.0 / 3628800 +
                                                                                      x2 * (1.0 / 479001600))))));
}

inline Terms terms_at(const Model& m, const Clock& ck, double t) {
  const double* p = m.p;
  (void)0;
  const double W = p[OMEGA];
  const double x = W * (t - ck.t);
  double sx, cx;
  small_sincos(x, &sx, &cx);
  double S[4], C[4];
  for (int k = 0; k < 4; ++k) {
    S[k] = ck.sn[k] * cx + ck.cs[k] * sx;
    C[k] = ck.cs[k] * cx - ck.sn[k] * sx;
  }
  Terms q;
  if (m.shape == 0) {
    q.ksp = p[KSM] + p[KSA] * S[0];
    q.krp = p[KRM] + p[KRA] * S[1];
  } else {
    q.ksp = p[KSM] + p[KSA] * wave(ck.ang[0] + x, p[CR_SP], 1);
    q.krp = p[KRM] + p[KRA] * wave(ck.ang[1] + x, p[CR_RP], 1);
  }
  const double e_sp = p[ESA] * S[2];
  const double de_sp = p[ESA] * W * C[2];
  const double dde_sp = -p[ESA] * W * W * S[2];
  q.E = e_sp + p[ERA] * S[3];
  q.dE = de_sp + p[ERA] * W * C[3];
  q.L1 = p[MU_S] * p[F_D] + p[MU_C] * p[F_L] - dde_sp;
  return q;
}

inline Terms terms_cached(const Model& m, const Clock& ck, TermCache& cache, double t) {
  for (int i = 0; i < cache.n; ++i)
    if (cache.t[i] == t) return cache.q[i];
  const Terms q = terms_at(m, ck, t);
  if (cache.n < 12) {
    cache.t[cache.n] = t;
    cache.q[cache.n++] = q;
  }
  return q;
}

inline double backlash(double X, double b) { return X >= b ? X - b : (X <= -b ? X + b : 0.0); }

struct Coef {  // state-independent coefficients of the reduced field
  double a2sp, a2rp, a4sp, a4rp, L2, b_sp, b_rp, c_sp, c_rp;
};

inline Coef coef(const Model& m) {
  const double* p = m.p;
  const double N = p[N_];
  Coef c;
  c.a2sp = -(N + p[MU_P]);
  c.a2rp = p[MU_P] - N * p[MU_C];
  c.a4sp = -N * (p[MU_S] + 2.0 * p[MU_C]);
  c.a4rp = -2.0 * N * p[MU_C];
  c.L2 = p[MU_S] * p[F_D] + 2.0 * p[MU_C] * p[F_L];
  c.b_sp = p[B_SP];
  c.b_rp = p[B_RP];
  c.c_sp = p[C_SP];
  c.c_rp = p[C_RP];
  return c;
}

inline void field(const Coef& c, const Terms& q, const double* x, double* dx) {
  const double X_rp = x[2] - x[0] - q.E;
  const double V_rp = x[3] - x[1] - q.dE;
  const double g_sp = q.ksp * backlash(x[0], c.b_sp) + c.c_sp * x[1];
  const double g_rp = q.krp * backlash(X_rp, c.b_rp) + c.c_rp * V_rp;
  dx[0] = x[1];
  dx[1] = c.a2sp * g_sp + c.a2rp * g_rp + q.L1;
  dx[2] = x[3];
  dx[3] = c.a4sp * g_sp + c.a4rp * g_rp + c.L2;
}

// The piece of the field on the sides `sd` (signs of the switching functions) of every
// surface, extended across them (the piece_field of jaxgear/_model.py).
inline double backlash_piece(double X, double b, double hi, double lo) {
  return hi > 0 ? X - b : (lo < 0 ? X + b : 0.0);
}

inline void field_piece(const Coef& c, const Terms& q, const double* x, const double* sd, double* dx) {
  if (!sd) {
    field(c, q, x, dx);
    return;
  }
  const double X_rp = x[2] - x[0] - q.E;
  const double V_rp = x[3] - x[1] - q.dE;
  const double g_sp = q.ksp * backlash_piece(x[0], c.b_sp, sd[0], sd[1]) + c.c_sp * x[1];
  const double g_rp = q.krp * backlash_piece(X_rp, c.b_rp, sd[2], sd[3]) + c.c_rp * V_rp;
  dx[0] = x[1];
  dx[1] = c.a2sp * g_sp + c.a2rp * g_rp + q.L1;
  dx[2] = x[3];
  dx[3] = c.a4sp * g_sp + c.a4rp * g_rp + c.L2;
}

inline void switching(const Coef& c, double E, const double* x, double* s) {
  const double X_rp = x[2] - x[0] - E;
  s[0] = x[0] - c.b_sp;
  s[1] = x[0] + c.b_sp;
  s[2] = X_rp - c.b_rp;
  s[3] = X_rp + c.b_rp;
}

inline void switching_rate(double dE, const double* f, double* d) {
  d[0] = d[1] = f[0];
  d[2] = d[3] = f[2] - f[0] - dE;
}

inline double side(double s) { return s >= 0.0 ? 1.0 : -1.0; }

inline double sgn(double v) { return v > 0.0 ? 1.0 : (v < 0.0 ? -1.0 : 0.0); }

// Fraction of the step [t, t + h] at which the first known time break lies (1: none).
inline double break_fraction(const Model& m, double t, double h) {
  if (m.n_breaks == 0) return 1.0;
  const double tol = kBreakTol * m.T;
  double best = 1.0;
  for (int j = 0; j < m.n_breaks; ++j) {
    const double wait = floor_mod(m.breaks[j] - t / m.T, 1.0) * m.T;
    if (wait > tol && wait < h - tol) best = std::min(best, wait / h);
  }
  return best;
}

// One RK4 step on one lane at arbitrary times (stage times kept inside the step when the
// model has time breaks), every stage on the piece `sd` (nullptr: the field itself).
// k1_in: the first stage when already known, else nullptr.
inline void rk4_lane(const Model& m, const Coef& c, const Clock& ck, TermCache& tc, double t, const double* y,
                     double h, const double* k1_in, double* out, double* k1_out, const double* sd) {
  const bool window = m.n_breaks > 0;
  double lo = 0, hi = 0;
  if (window) {
    const double tol = std::min(kBreakTol * m.T, 0.25 * std::fabs(h));
    lo = t + tol;
    hi = t + h - tol;
  }
  auto tm = [&](double s) { return window ? std::min(std::max(s, lo), hi) : s; };
  double k1[4], k2[4], k3[4], k4[4], z[4];
  const double h2 = 0.5 * h;
  if (k1_in) {
    for (int i = 0; i < 4; ++i) k1[i] = k1_in[i];
  } else {
    field_piece(c, terms_cached(m, ck, tc, tm(t)), y, sd, k1);
  }
  for (int i = 0; i < 4; ++i) z[i] = y[i] + h2 * k1[i];
  const Terms qm = terms_cached(m, ck, tc, tm(t + h2));
  field_piece(c, qm, z, sd, k2);
  for (int i = 0; i < 4; ++i) z[i] = y[i] + h2 * k2[i];
  field_piece(c, qm, z, sd, k3);
  for (int i = 0; i < 4; ++i) z[i] = y[i] + h * k3[i];
  field_piece(c, terms_cached(m, ck, tc, tm(t + h)), z, sd, k4);
  for (int i = 0; i < 4; ++i) out[i] = y[i] + (h / 6.0) * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
  if (k1_out)
    for (int i = 0; i < 4; ++i) k1_out[i] = k1[i];
}

// Root in (0, 1) of the cubic Hermite interpolant (as _kink._hermite_root).
inline double hermite_root(double s0, double s1, double d0, double d1) {
  auto p = [&](double th) {
    const double t2 = th * th, t3 = t2 * th;
    return (2 * t3 - 3 * t2 + 1) * s0 + (t3 - 2 * t2 + th) * d0 + (-2 * t3 + 3 * t2) * s1 + (t3 - t2) * d1;
  };
  auto dp = [&](double th) {
    const double t2 = th * th;
    return (6 * t2 - 6 * th) * s0 + (3 * t2 - 4 * th + 1) * d0 + (-6 * t2 + 6 * th) * s1 + (3 * t2 - 2 * th) * d1;
  };
  const double denom = s0 - s1;
  double th = denom != 0 ? s0 / denom : 0.5;
  th = std::min(std::max(th, 0.0), 1.0);
  double lo = 0.0, hi = 1.0;
  const double sg0 = sgn(s0);
  for (int it = 0; it < kHermiteIters; ++it) {
    const double v = p(th);
    if (sgn(v) == sg0) lo = th; else hi = th;
    const double d = dp(th);
    double nt = th - v / (d != 0 ? d : 1.0);
    const bool done = v == 0 || (d != 0 && std::fabs(nt - th) <= 4.0 * kEps);
    if (!(nt > lo && nt < hi && d != 0)) nt = 0.5 * (lo + hi);
    if (done) break;  // later iterations would keep th: the same result as the fixed count
    th = nt;
  }
  const double d = dp(th);
  return th - p(th) / (d != 0 ? d : 1.0);
}

// The earliest event of a trial step of one lane (as _kink._first_crossing): theta, the
// index of the crossed function (-1: a time break or none), and in `flips` every function
// crossed at that same instant (b = 0, where both sides of a backlash coincide).
inline void first_crossing(const Model& m, const Coef& c, const Clock& ck, TermCache& tc, double t, double h,
                           const double* y, const double* y1,
                           const double* k1, const double* S0, const double* S1, const double* sides, double thb,
                           double* theta, int* which, bool* flips) {
  double th_s = 2.0, th[4] = {2.0, 2.0, 2.0, 2.0};
  int j = 0;
  bool any = false;
  for (int i = 0; i < 4; ++i)
    if (side(S1[i]) != sides[i] && std::isfinite(S1[i]) && std::isfinite(S0[i])) any = true;
  if (any) {
    double F1[4], D0[4], D1[4];
    const Terms qe = terms_cached(m, ck, tc, t + h);
    field(c, qe, y1, F1);
    switching_rate(terms_cached(m, ck, tc, t).dE, k1, D0);
    switching_rate(qe.dE, F1, D1);
    for (int i = 0; i < 4; ++i) {
      if (side(S1[i]) != sides[i] && std::isfinite(S1[i]) && std::isfinite(S0[i])) {
        th[i] = hermite_root(S0[i], S1[i], D0[i] * h, D1[i] * h);
        th[i] = std::min(std::max(th[i], 0.0), 1.0);
      }
      if (th[i] < th_s) {
        th_s = th[i];
        j = i;
      }
    }
  }
  const bool use_break = thb < th_s;
  *which = (use_break || th_s > 1.0) ? -1 : j;
  *theta = std::min(use_break ? thb : th_s, 1.0);
  for (int i = 0; i < 4; ++i) flips[i] = *which >= 0 && th[i] <= th_s + kSimultaneous;
}

// Put the end of the sub-step to a crossing on the crossed surface (as _kink._land): one
// Newton correction along the piece being left.
inline void land(const Model& m, const Coef& c, const Clock& ck, TermCache& tc, double t, double* Ym, double* h1,
                 double h, int which, const double* sides) {
  if (which < 0) return;
  const double tm = t + *h1;
  double te = tm;
  if (m.n_breaks > 0) te = std::max(tm, t + std::min(kBreakTol * m.T, 0.25 * std::fabs(*h1)));
  double F[4], S[4], D[4];
  field_piece(c, terms_cached(m, ck, tc, te), Ym, sides, F);
  const Terms qm = terms_cached(m, ck, tc, tm);
  switching(c, qm.E, Ym, S);
  switching_rate(qm.dE, F, D);
  const double rate = D[which];
  const double dt = -S[which] / (rate != 0 ? rate : 1.0);
  if (!(rate != 0 && std::isfinite(dt) && std::fabs(dt) <= 0.25 * std::fabs(h))) return;
  for (int i = 0; i < 4; ++i) Ym[i] += F[i] * dt;
  *h1 += dt;
}

// A lane whose trial step holds an event (as _kink._split): sub-steps on their own pieces.
inline void split_lane(const Model& m, const Coef& c, const Clock& ck, TermCache& tc, double t, double h,
                       const double* y, const double* k1,
                       double th, int which, const bool* flips_in, double* sides, int max_splits, double* out) {
  const bool window = m.n_breaks > 0;
  double tt = t, hh = h, Y[4], K1[4];
  bool flips[4];
  for (int i = 0; i < 4; ++i) {
    Y[i] = y[i];
    K1[i] = k1[i];
    flips[i] = flips_in[i];
  }
  for (int it = 0; it < max_splits; ++it) {
    double h1 = th * hh;
    double Ym[4];
    rk4_lane(m, c, ck, tc, tt, Y, h1, window ? nullptr : K1, Ym, nullptr, sides);
    land(m, c, ck, tc, tt, Ym, &h1, hh, which, sides);
    for (int i = 0; i < 4; ++i)
      if (flips[i]) sides[i] = -sides[i];
    tt = tt + h1;
    hh = hh - h1;
    double Y1[4];
    rk4_lane(m, c, ck, tc, tt, Ym, hh, nullptr, Y1, K1, sides);
    if (it == max_splits - 1) {
      for (int i = 0; i < 4; ++i) out[i] = Y1[i];
      return;
    }
    double S0[4], S1[4];
    switching(c, terms_cached(m, ck, tc, tt + hh).E, Y1, S1);
    switching(c, terms_cached(m, ck, tc, tt).E, Ym, S0);
    const double thb = break_fraction(m, tt, hh);
    double th2;
    int which2;
    bool flips2[4];
    first_crossing(m, c, ck, tc, tt, hh, Ym, Y1, K1, S0, S1, sides, thb, &th2, &which2, flips2);
    const bool more = th2 < 1.0;
    if (it == max_splits - 2) {
      if (!more) {
        for (int i = 0; i < 4; ++i) out[i] = Y1[i];
        return;
      }
      double fin[4], h2 = th2 * hh;
      rk4_lane(m, c, ck, tc, tt, Ym, h2, window ? nullptr : K1, fin, nullptr, sides);
      land(m, c, ck, tc, tt, fin, &h2, hh, which2, sides);
      for (int i = 0; i < 4; ++i)
        if (flips2[i]) sides[i] = -sides[i];
      rk4_lane(m, c, ck, tc, tt + h2, fin, hh - h2, nullptr, out, nullptr, sides);
      return;
    }
    for (int i = 0; i < 4; ++i) {
      Y[i] = Ym[i];
      flips[i] = more && flips2[i];
    }
    th = more ? th2 : 1.0;
    which = more ? which2 : -1;
  }
}

// Eight lanes in one vector register (GCC vector extensions).
typedef double v8d __attribute__((vector_size(64)));
typedef long long v8l __attribute__((vector_size(64)));

inline v8d load8(const double* p) {
  v8d v;
  __builtin_memcpy(&v, p, sizeof v);
  return v;
}

inline void store8(double* p, v8d v) { __builtin_memcpy(p, &v, sizeof v); }

template <class V>
inline V loadv(const double* p) {
  V v;
  __builtin_memcpy(&v, p, sizeof v);
  return v;
}
template <class V>
inline void storev(double* p, V v) {
  __builtin_memcpy(p, &v, sizeof v);
}

struct Table {  // per parameter row: the time-only terms at every stage time of one period
  int steps;
  std::vector<Terms> stage;  // [steps][3]
  std::vector<double> E0, E1, thb;  // E at a step's start and end, break fraction per step
  std::vector<Clock> clock;         // trigonometry at each step's start
};

Table tabulate(const Model& m, double t0, double h, int steps) {
  Table tb;
  tb.steps = steps;
  tb.stage.resize(3 * steps);
  tb.E0.resize(steps);
  tb.E1.resize(steps);
  tb.thb.resize(steps);
  tb.clock.resize(steps);
  const bool window = m.n_breaks > 0;
  const double tol = window ? std::min(kBreakTol * m.T, 0.25 * std::fabs(h)) : 0.0;
  for (int i = 0; i < steps; ++i) {
    const double t = t0 + i * h;
    double ts[3] = {t, t + 0.5 * h, t + h};
    if (window)
      for (double& s : ts) s = std::min(std::max(s, t + tol), t + h - tol);
    for (int s = 0; s < 3; ++s) tb.stage[3 * i + s] = terms(m, ts[s]);
    tb.E0[i] = terms(m, t).E;
    tb.E1[i] = terms(m, t + h).E;
    tb.thb[i] = break_fraction(m, t, h);
    tb.clock[i] = make_clock(m, t);
  }
  return tb;
}

Model make_model(const double* row, int shape) {
  Model m;
  for (int i = 0; i < NPARAM; ++i) m.p[i] = row[i];
  m.shape = shape;
  m.T = 2.0 * kPi / m.p[OMEGA];
  m.n_breaks = 0;
  if (shape == 1) {
    const double pairs[2][2] = {{m.p[PHI_SP], m.p[CR_SP]}, {m.p[PHI_RP], m.p[CR_RP]}};
    for (auto& pr : pairs) {
      const double d = pr[1] - 1.0;
      const double edges[2] = {0.5 * kPi - kPi * d, 0.5 * kPi + kPi * d};
      for (double e : edges) m.breaks[m.n_breaks++] = floor_mod((e - pr[0]) / (2.0 * kPi), 1.0);
    }
  }
  return m;
}


// Tables of recent parameter rows. A period's table depends only on the row, the wave shape,
// the start time and the steps, and a pool or a candidate's cloud asks for the same one every
// period: tabulating (a few thousand sines) is most of what a call on a few lanes costs.
// Bounded (kCachedTables, replaced in turn); a row is matched bit for bit, so a cached table
// is exactly the one tabulate would compute.
constexpr size_t kCachedTables = 64;
using TableKey = std::array<uint64_t, NPARAM + 3>;

TableKey table_key(const double* row, int shape, double t0, int64_t steps) {
  TableKey k{};
  std::memcpy(k.data(), row, NPARAM * sizeof(double));
  std::memcpy(&k[NPARAM], &t0, sizeof(double));
  k[NPARAM + 1] = static_cast<uint64_t>(steps);
  k[NPARAM + 2] = static_cast<uint64_t>(shape);
  return k;
}

class TableCache {
 public:
  std::shared_ptr<const Table> get(const Model& m, const TableKey& key, double t0, int steps) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      for (const auto& item : items_)
        if (item.first == key) return item.second;
    }
    auto tb = std::make_shared<const Table>(tabulate(m, t0, m.T / steps, steps));
    std::lock_guard<std::mutex> lock(mu_);
    if (items_.size() < kCachedTables) {
      items_.emplace_back(key, tb);
    } else {
      items_[next_] = {key, tb};
      next_ = (next_ + 1) % kCachedTables;
    }
    return tb;
  }

 private:
  std::mutex mu_;
  std::vector<std::pair<TableKey, std::shared_ptr<const Table>>> items_;
  size_t next_ = 0;
};

TableCache& table_cache() {
  static TableCache cache;
  return cache;
}

// The trial step's registers: eight lanes with AVX-512, four otherwise (a register of the
// machine: wider generic vectors would be split into pieces by the compiler).
typedef double v4d __attribute__((vector_size(32)));
typedef long long v4l __attribute__((vector_size(32)));
#ifdef __AVX512F__
typedef v8d vtd;
#else
typedef v4d vtd;
#endif
constexpr int kTrialLanes = sizeof(vtd) / sizeof(double);
constexpr int kTrialGroups = 4;  // registers advanced together (independent chains overlap)

// The bits of a lane mask of the trial's registers (lane i: bit i).
template <class M>
inline unsigned lane_bits(M m) {
#ifdef __AVX512F__
  if constexpr (sizeof(M) == 64)
    return _mm512_test_epi64_mask(reinterpret_cast<__m512i>(m), reinterpret_cast<__m512i>(m));
#elif defined(__AVX__)
  if constexpr (sizeof(M) == 32) return static_cast<unsigned>(_mm256_movemask_pd(reinterpret_cast<__m256d>(m)));
#endif
  unsigned bits = 0;
  for (int i = 0; i < static_cast<int>(sizeof(M) / 8); ++i) bits |= (m[i] != 0 ? 1u : 0u) << i;
  return bits;
}

// The bits of the lanes where x >= b (false for a NaN), as a mask straight from the compare.
template <class V>
inline unsigned ge_bits(V x, double b) {
#ifdef __AVX512F__
  if constexpr (sizeof(V) == 64)
    return _mm512_cmp_pd_mask(reinterpret_cast<__m512d>(x), _mm512_set1_pd(b), _CMP_GE_OQ);
#endif
  return lane_bits(x >= b);
}

// The dead zone x - b (x >= b), 0 (|x| < b), x + b (x <= -b) on a register of lanes, as x
// minus x clamped to [-b, b]: the same values as backlash() (exact: the clamp is x, b or -b;
// a NaN stays NaN), three instructions.
template <class V>
inline V dead_zone(V x, double b) {
#ifdef __AVX512F__
  if constexpr (sizeof(V) == 64) {
    const __m512d v = reinterpret_cast<__m512d>(x);
    return reinterpret_cast<V>(_mm512_sub_pd(v, _mm512_max_pd(_mm512_min_pd(v, _mm512_set1_pd(b)),
                                                              _mm512_set1_pd(-b))));
  }
#endif
#ifdef __AVX__
  if constexpr (sizeof(V) == 32) {
    const __m256d v = reinterpret_cast<__m256d>(x);
    return reinterpret_cast<V>(_mm256_sub_pd(v, _mm256_max_pd(_mm256_min_pd(v, _mm256_set1_pd(b)),
                                                              _mm256_set1_pd(-b))));
  }
#endif
  const V zero = {}, l = x - b, u = x + b;  // max(x - b, 0) + min(x + b, 0)
  return (l < 0.0 ? zero : l) + (0.0 < u ? zero : u);
}

// The trial RK4 step of a block whose lanes share one parameter row, vectorised over the
// lanes (the four stages of G registers of lanes at once): y (4 x G registers) -> e, and
// whether the step of each lane changes the side of a switching function (bits[g]).
template <class V, int G>
inline void trial_groups(const Coef& c, const Terms& q0, const Terms& q1, const Terms& q2, double h, double E0,
                         double E1, const V* y0, const V* y1, const V* y2, const V* y3, V* e0, V* e1, V* e2, V* e3,
                         unsigned* bits) {
  const double h2 = 0.5 * h, h6 = h / 6.0;
  const double bsp = c.b_sp, brp = c.b_rp, csp = c.c_sp, crp = c.c_rp;
  const double a2sp = c.a2sp, a2rp = c.a2rp, a4sp = c.a4sp, a4rp = c.a4rp, L2 = c.L2;
  auto f = [&](const Terms& q, V z0, V z1, V z2, V z3, V& v1, V& v3) __attribute__((always_inline)) {
    const V X = z2 - z0 - q.E, Vr = z3 - z1 - q.dE;
    const V fsp = dead_zone(z0, bsp), frp = dead_zone(X, brp);
    const V gsp = q.ksp * fsp + csp * z1, grp = q.krp * frp + crp * Vr;
    v1 = a2sp * gsp + a2rp * grp + q.L1;
    v3 = a4sp * gsp + a4rp * grp + L2;
  };
  V a1[G], a3[G], b1[G], b3[G], c1[G], c3[G], d1[G], d3[G];
  V u0[G], u1[G], u2[G], u3[G], v0[G], v1[G], v2[G], v3[G], w0[G], w1[G], w2[G], w3[G];
#pragma GCC unroll 8
  for (int g = 0; g < G; ++g) f(q0, y0[g], y1[g], y2[g], y3[g], a1[g], a3[g]);
#pragma GCC unroll 8
  for (int g = 0; g < G; ++g) {
    u0[g] = y0[g] + h2 * y1[g], u1[g] = y1[g] + h2 * a1[g], u2[g] = y2[g] + h2 * y3[g], u3[g] = y3[g] + h2 * a3[g];
    f(q1, u0[g], u1[g], u2[g], u3[g], b1[g], b3[g]);
  }
#pragma GCC unroll 8
  for (int g = 0; g < G; ++g) {
    v0[g] = y0[g] + h2 * u1[g], v1[g] = y1[g] + h2 * b1[g], v2[g] = y2[g] + h2 * u3[g], v3[g] = y3[g] + h2 * b3[g];
    f(q1, v0[g], v1[g], v2[g], v3[g], c1[g], c3[g]);
  }
#pragma GCC unroll 8
  for (int g = 0; g < G; ++g) {
    w0[g] = y0[g] + h * v1[g], w1[g] = y1[g] + h * c1[g], w2[g] = y2[g] + h * v3[g], w3[g] = y3[g] + h * c3[g];
    f(q2, w0[g], w1[g], w2[g], w3[g], d1[g], d3[g]);
  }
#pragma GCC unroll 8
  for (int g = 0; g < G; ++g) {
    e0[g] = y0[g] + h6 * (y1[g] + 2.0 * (u1[g] + v1[g]) + w1[g]);
    e1[g] = y1[g] + h6 * (a1[g] + 2.0 * (b1[g] + c1[g]) + d1[g]);
    e2[g] = y2[g] + h6 * (y3[g] + 2.0 * (u3[g] + v3[g]) + w3[g]);
    e3[g] = y3[g] + h6 * (a3[g] + 2.0 * (b3[g] + c3[g]) + d3[g]);
    // (lanes that are not finite are told apart in the split: lane_finite)
    const V X0 = y2[g] - y0[g] - E0, X1 = e2[g] - e0[g] - E1;
    // (x - b >= 0 is x >= b, x + b >= 0 is x >= -b: the sign of a rounded difference is exact)
    bits[g] = (ge_bits(y0[g], bsp) ^ ge_bits(e0[g], bsp)) | (ge_bits(y0[g], -bsp) ^ ge_bits(e0[g], -bsp)) |
              (ge_bits(X0, brp) ^ ge_bits(X1, brp)) | (ge_bits(X0, -brp) ^ ge_bits(X1, -brp));
  }
}

// The trial step of the L lanes of x (one parameter row): x (4 x L) -> x1, and whether the
// step of a lane holds an event (a switching function changes sign, or a known time break
// `brk`) as bits: bit i of need[k] for lane 64 k + i (the bits past L are zero).
__attribute__((noinline)) void trial_uniform(const Coef& c, const Terms& q0, const Terms& q1, const Terms& q2,
                                             double h, int L, const double (*x)[kRow], double (*x1)[kRow],
                                             double E0, double E1, bool brk, uint64_t* need) {
  typedef vtd V;
  constexpr int G = kTrialGroups, W = kTrialLanes;
  const unsigned all = brk ? (1u << W) - 1u : 0u;
  for (int k = 0; 64 * k < L; ++k) need[k] = 0;
  int j = 0;
  for (; j + W * G <= L; j += W * G) {
    V y[4][G], e[4][G];
    unsigned bits[G];
#pragma GCC unroll 8
    for (int g = 0; g < G; ++g)
      for (int i = 0; i < 4; ++i) y[i][g] = loadv<V>(x[i] + j + W * g);
    trial_groups<V, G>(c, q0, q1, q2, h, E0, E1, y[0], y[1], y[2], y[3], e[0], e[1], e[2], e[3], bits);
#pragma GCC unroll 8
    for (int g = 0; g < G; ++g) {
      for (int i = 0; i < 4; ++i) storev(x1[i] + j + W * g, e[i][g]);
      need[(j + W * g) / 64] |= static_cast<uint64_t>(bits[g] | all) << ((j + W * g) % 64);
    }
  }
  for (; j < L; j += W) {  // the last lanes, one register at a time, through a padded copy (the same instructions)
    const int r = std::min(W, L - j);
    alignas(64) double y[4][W] = {}, e[4][W];
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < r; ++k) y[i][k] = x[i][j + k];
    V yv[4], ev[4];
    unsigned bits;
    for (int i = 0; i < 4; ++i) yv[i] = loadv<V>(y[i]);
    trial_groups<V, 1>(c, q0, q1, q2, h, E0, E1, yv, yv + 1, yv + 2, yv + 3, ev, ev + 1, ev + 2, ev + 3, &bits);
    for (int i = 0; i < 4; ++i) storev(e[i], ev[i]);
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < r; ++k) x1[i][j + k] = e[i][k];
    need[j / 64] |= static_cast<uint64_t>((bits | all) & ((1u << r) - 1u)) << (j % 64);
  }
}

// Whether a lane's sign test is meaningful (its step is split only then, unless a time break
// lies inside the step): the crossing coordinates finite at both ends of the trial step.
inline bool lane_finite(double E0, double E1, const double* y, const double* y1) {
  const double X0 = y[2] - y[0] - E0, X1 = y1[2] - y1[0] - E1;
  return (y1[0] - y1[0] == 0.0) & (X1 - X1 == 0.0) & (y[0] - y[0] == 0.0) & (X0 - X0 == 0.0);
}

// Whether the split of a row's lanes can run vectorised (split_block): no time breaks (the
// sine mesh stiffness), and every time met inside a step close enough to its start for the
// short series of small_sincos (|W (tau - t)| <= 1.25 W h plus round-off, below 0.2).
inline bool vector_split_ok(const Model& m, double h) { return m.n_breaks == 0 && 1.3 * m.p[OMEGA] * h <= 0.2; }

// Scratch of split_block: the lanes of a block that split in one step, struct of arrays.
struct SplitScratch {
  alignas(64) double y[4][kRow], k1[4][kRow], ym[4][kRow], y1[4][kRow], sd[4][kRow];
  alignas(64) double th[kBlock], tt[kBlock], hh[kBlock];
  alignas(64) double s0[4 * kBlock + 8], s1[4 * kBlock + 8], d0[4 * kBlock + 8], d1[4 * kBlock + 8];
  alignas(64) double root[4 * kBlock + 8];
  alignas(64) double S0[4][kRow], S1[4][kRow], D0[4][kRow], D1[4][kRow];
  alignas(64) double thl[4][kRow], lo[4 * kBlock], hi[4 * kBlock], sg0[4 * kBlock];
  alignas(64) double wh[kBlock], fl[4][kRow], fin[kBlock];
  alignas(64) long long actl[4 * kBlock];
  alignas(64) unsigned cont[kBlock / 8], done[kBlock / 8];
  alignas(64) int pair_lane[4 * kBlock + 8], pair_fn[4 * kBlock + 8];
};

// Roots of the Hermite cubics of `np` crossings at once: hermite_root on eight at a time
// (GCC vector extensions; the selects and the arithmetic of hermite_root, the loop left when
// all eight have converged: each root keeps its own iterations). The inputs are padded to
// a multiple of eight with a harmless cubic, so every root takes the same instructions
// wherever it stands.

inline void hermite_roots(SplitScratch& w, int np) {
  const int np8 = (np + 7) / 8 * 8;
  for (int k = np; k < np8; ++k) {
    w.s0[k] = 1.0;
    w.s1[k] = -1.0;
    w.d0[k] = 0.0;
    w.d1[k] = 0.0;
  }
  const v8d zero = {}, one = zero + 1.0;
  // the iterations of all groups of eight interleaved (independent chains: they overlap)
  auto p = [](v8d th, v8d s0, v8d s1, v8d d0, v8d d1) __attribute__((always_inline)) {
    const v8d t2 = th * th, t3 = t2 * th;
    return (2.0 * t3 - 3.0 * t2 + 1.0) * s0 + (t3 - 2.0 * t2 + th) * d0 + (-2.0 * t3 + 3.0 * t2) * s1 +
           (t3 - t2) * d1;
  };
  auto dp = [](v8d th, v8d s0, v8d s1, v8d d0, v8d d1) __attribute__((always_inline)) {
    const v8d t2 = th * th;
    return (6.0 * t2 - 6.0 * th) * s0 + (3.0 * t2 - 4.0 * th + 1.0) * d0 + (-6.0 * t2 + 6.0 * th) * s1 +
           (3.0 * t2 - 2.0 * th) * d1;
  };
  auto store = [](double* dst, v8d v) { __builtin_memcpy(dst, &v, sizeof v); };
  for (int k0 = 0; k0 < np8; k0 += 8) {
    const v8d s0 = load8(w.s0 + k0), s1 = load8(w.s1 + k0);
    const v8d denom = s0 - s1;
    const v8d q = s0 / (denom != 0.0 ? denom : one);
    v8d th = denom != 0.0 ? q : zero + 0.5;
    th = th < 0.0 ? zero : th;  // std::max(th, 0.0)
    th = 1.0 < th ? one : th;   // std::min(th, 1.0)
    store(w.root + k0, th);
    store(w.lo + k0, zero);
    store(w.hi + k0, one);
    store(w.sg0 + k0, s0 > 0.0 ? one : (s0 < 0.0 ? -one : zero));
    const v8l all = zero == zero;
    __builtin_memcpy(w.actl + k0, &all, sizeof all);
  }
  for (int it = 0; it < kHermiteIters; ++it) {
    v8l left = zero != zero;
    for (int k0 = 0; k0 < np8; k0 += 8) {
      const v8d s0 = load8(w.s0 + k0), s1 = load8(w.s1 + k0), d0 = load8(w.d0 + k0), d1 = load8(w.d1 + k0);
      v8d th = load8(w.root + k0), lo = load8(w.lo + k0), hi = load8(w.hi + k0);
      const v8d sg0 = load8(w.sg0 + k0);
      v8l act;
      __builtin_memcpy(&act, w.actl + k0, sizeof act);
      const v8d v = p(th, s0, s1, d0, d1), d = dp(th, s0, s1, d0, d1);
      const v8d sv = v > 0.0 ? one : (v < 0.0 ? -one : zero);
      const v8l same = sv == sg0;
      const v8d nlo = same ? th : lo, nhi = same ? hi : th;
      const v8l dnz = d != 0.0;
      const v8d nn = th - v / (dnz ? d : one), mid = 0.5 * (nlo + nhi);
      const v8d step = nn - th;
      const v8d ast = step < 0.0 ? -step : step;
      const v8l done = (v == 0.0) | (dnz & (ast <= 4.0 * kEps));
      const v8l inside = (nn > nlo) & (nn < nhi) & dnz;
      const v8d nt = inside ? nn : mid;
      lo = act ? nlo : lo;
      hi = act ? nhi : hi;
      act = act & ~done;
      th = act ? nt : th;
      store(w.root + k0, th);
      store(w.lo + k0, lo);
      store(w.hi + k0, hi);
      __builtin_memcpy(w.actl + k0, &act, sizeof act);
      left |= act;
    }
    const v8l a4 = left | __builtin_shufflevector(left, left, 4, 5, 6, 7, 0, 1, 2, 3);
    const v8l a2 = a4 | __builtin_shufflevector(a4, a4, 2, 3, 0, 1, 6, 7, 4, 5);
    if (!(a2[0] | a2[1])) break;
  }
  for (int k0 = 0; k0 < np8; k0 += 8) {
    const v8d s0 = load8(w.s0 + k0), s1 = load8(w.s1 + k0), d0 = load8(w.d0 + k0), d1 = load8(w.d1 + k0);
    const v8d th = load8(w.root + k0);
    const v8d d = dp(th, s0, s1, d0, d1);
    store(w.root + k0, th - p(th, s0, s1, d0, d1) / (d != 0.0 ? d : one));
  }
}

// The split of the lanes `idx[0..K)` of a block (all of one parameter row, vector_split_ok)
// in step s from t: the arithmetic of first_crossing and split_lane, with the crossing, the
// sub-step to it, the landing and the rest of the step done eight lanes at a time (every
// lane through the same instructions, so its result does not depend on its neighbours);
// the few lanes with a further event in the same step (or max_splits > 2) continue lane by
// lane. Lanes that are not finite keep their trial step (lane_finite). x: the states at t,
// x1: the trial states at t + h, overwritten with the split ones.
void split_block(const Model& m, const Coef& c, const Table& tb, int s, double t, double h, int max_splits,
                 const int* idx, int K, const double (*x)[kRow], double (*x1)[kRow], SplitScratch& w) {
  const double* p = m.p;
  const Clock& ck = tb.clock[s];
  const Terms q0 = tb.stage[3 * s], q2 = tb.stage[3 * s + 2];
  const double te = t + h, E0 = tb.E0[s], E1 = tb.E1[s];
  // the crossing of the trial step (first_crossing): switching functions and rates at both
  // ends, vectorised over the lanes (padded to a multiple of eight with copies of the last
  // one, whose results are dropped), then the crossed functions gathered for hermite_roots
  const int Kp = (K + 7) / 8 * 8;
  int ix[kBlock];
  for (int g = 0; g < Kp; ++g) ix[g] = idx[g < K ? g : K - 1];
  double (*S0a)[kRow] = w.S0;
  double (*S1a)[kRow] = w.S1;
  double (*D0a)[kRow] = w.D0;
  double (*D1a)[kRow] = w.D1;
  const double bsp = c.b_sp, brp = c.b_rp, csp = c.c_sp, crp = c.c_rp;
  const double a2sp = c.a2sp, a2rp = c.a2rp, a4sp = c.a4sp, a4rp = c.a4rp, L2 = c.L2;
#pragma omp simd simdlen(8)
  for (int g = 0; g < Kp; ++g) {
    // field(q0, y) (k1), switching at both ends, switching_rate at both ends (field(q2, y1)
    // enters through its position components only), on scalars
    const int j = ix[g];
    const double y0 = x[0][j], y1 = x[1][j], y2 = x[2][j], y3 = x[3][j];
    const double e0 = x1[0][j], e1 = x1[1][j], e2 = x1[2][j], e3 = x1[3][j];
    const double X = y2 - y0 - q0.E, V = y3 - y1 - q0.dE;
    const double zl = y0 - bsp, zh = y0 + bsp, Xl = X - brp, Xh = X + brp;
    const double fsp = y0 >= bsp ? zl : (y0 <= -bsp ? zh : 0.0);
    const double frp = X >= brp ? Xl : (X <= -brp ? Xh : 0.0);
    const double gsp = q0.ksp * fsp + csp * y1, grp = q0.krp * frp + crp * V;
    const double k1v = a2sp * gsp + a2rp * grp + q0.L1, k3v = a4sp * gsp + a4rp * grp + L2;
    const double Xa = y2 - y0 - E0, Xb = e2 - e0 - E1;
    w.fin[g] = (e0 - e0 == 0.0) & (Xb - Xb == 0.0) & (y0 - y0 == 0.0) & (Xa - Xa == 0.0) ? 1.0 : 0.0;
    const double S00 = y0 - bsp, S01 = y0 + bsp, S02 = Xa - brp, S03 = Xa + brp;
    const double S10 = e0 - bsp, S11 = e0 + bsp, S12 = Xb - brp, S13 = Xb + brp;
    const double r0 = y3 - y1 - q0.dE, r1 = e3 - e1 - q2.dE;
    w.y[0][g] = y0;
    w.y[1][g] = y1;
    w.y[2][g] = y2;
    w.y[3][g] = y3;
    w.k1[0][g] = y1;
    w.k1[1][g] = k1v;
    w.k1[2][g] = y3;
    w.k1[3][g] = k3v;
    w.sd[0][g] = S00 >= 0.0 ? 1.0 : -1.0;
    w.sd[1][g] = S01 >= 0.0 ? 1.0 : -1.0;
    w.sd[2][g] = S02 >= 0.0 ? 1.0 : -1.0;
    w.sd[3][g] = S03 >= 0.0 ? 1.0 : -1.0;
    S0a[0][g] = S00;
    S0a[1][g] = S01;
    S0a[2][g] = S02;
    S0a[3][g] = S03;
    S1a[0][g] = S10;
    S1a[1][g] = S11;
    S1a[2][g] = S12;
    S1a[3][g] = S13;
    for (int i = 0; i < 4; ++i) w.thl[i][g] = 2.0;
    D0a[0][g] = y1;
    D0a[1][g] = y1;
    D0a[2][g] = r0;
    D0a[3][g] = r0;
    D1a[0][g] = e1;
    D1a[1][g] = e1;
    D1a[2][g] = r1;
    D1a[3][g] = r1;
  }
  int np = 0;
#if defined(__AVX512F__) && defined(__AVX512VL__)
  {  // the crossed functions of eight lanes at a time, packed to the front of a register
    const v8d one = v8d{} + 1.0;
    const __m256i iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    for (int g0 = 0; g0 < K; g0 += 8) {
      const unsigned valid = K - g0 >= 8 ? 0xffu : (1u << (K - g0)) - 1u;
      const unsigned fin = valid & lane_bits(load8(w.fin + g0) != 0.0);  // not finite: the trial step stands
      const __m256i lanes = _mm256_add_epi32(iota, _mm256_set1_epi32(g0));
      for (int i = 0; i < 4; ++i) {
        const v8d S0 = load8(S0a[i] + g0), S1 = load8(S1a[i] + g0);
        const __mmask8 k = static_cast<__mmask8>(
            fin & lane_bits(((S1 >= 0.0 ? one : -one) != load8(w.sd[i] + g0)) & (S1 - S1 == 0.0) & (S0 - S0 == 0.0)));
        auto pack = [k](v8d v) {
          return reinterpret_cast<v8d>(_mm512_maskz_compress_pd(k, reinterpret_cast<__m512d>(v)));
        };
        store8(w.s0 + np, pack(S0));
        store8(w.s1 + np, pack(S1));
        store8(w.d0 + np, pack(load8(D0a[i] + g0) * h));
        store8(w.d1 + np, pack(load8(D1a[i] + g0) * h));
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(w.pair_lane + np), _mm256_maskz_compress_epi32(k, lanes));
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(w.pair_fn + np), _mm256_set1_epi32(i));
        np += __builtin_popcount(k);
      }
    }
  }
#else
  for (int g = 0; g < K; ++g) {
    // (written whatever the test, kept when it holds: no branch to mispredict)
    const bool fin = w.fin[g] != 0.0;  // not finite: the trial step stands (lane_finite)
    for (int i = 0; i < 4; ++i) {
      const double S0 = S0a[i][g], S1 = S1a[i][g];
      w.s0[np] = S0;
      w.s1[np] = S1;
      w.d0[np] = D0a[i][g] * h;
      w.d1[np] = D1a[i][g] * h;
      w.pair_lane[np] = g;
      w.pair_fn[np] = i;
      np += fin & (side(S1) != w.sd[i][g]) & (S1 - S1 == 0.0) & (S0 - S0 == 0.0);
    }
  }
#endif
  hermite_roots(w, np);
  for (int k = 0; k < np; ++k) w.thl[w.pair_fn[k]][w.pair_lane[k]] = std::min(std::max(w.root[k], 0.0), 1.0);
  // the first crossing of each lane (as first_crossing), eight lanes at a time
  const double thb = tb.thb[s];
  for (int g0 = 0; g0 < Kp; g0 += 8) {
    const v8d zero = {}, one = zero + 1.0;
    const v8d t0 = load8(w.thl[0] + g0), t1 = load8(w.thl[1] + g0), t2 = load8(w.thl[2] + g0),
              t3 = load8(w.thl[3] + g0);
    v8d th_s = zero + 2.0, jf = zero;  // the first smallest
    jf = t0 < th_s ? zero : jf;
    th_s = t0 < th_s ? t0 : th_s;
    jf = t1 < th_s ? one : jf;
    th_s = t1 < th_s ? t1 : th_s;
    jf = t2 < th_s ? zero + 2.0 : jf;
    th_s = t2 < th_s ? t2 : th_s;
    jf = t3 < th_s ? zero + 3.0 : jf;
    th_s = t3 < th_s ? t3 : th_s;
    const v8l use_break = thb < th_s;
    const v8d which = use_break ? -one : (th_s > 1.0 ? -one : jf);
    v8d th = use_break ? zero + thb : th_s;
    th = 1.0 < th ? one : th;  // std::min(th, 1.0)
    const v8d lim = th_s + kSimultaneous;
    const v8l any = which >= 0.0;
    const v8d f0 = any & (t0 <= lim) ? -one : one, f1 = any & (t1 <= lim) ? -one : one;
    const v8d f2 = any & (t2 <= lim) ? -one : one, f3 = any & (t3 <= lim) ? -one : one;
    __builtin_memcpy(w.wh + g0, &which, sizeof which);
    __builtin_memcpy(w.th + g0, &th, sizeof th);
    __builtin_memcpy(w.fl[0] + g0, &f0, sizeof f0);
    __builtin_memcpy(w.fl[1] + g0, &f1, sizeof f1);
    __builtin_memcpy(w.fl[2] + g0, &f2, sizeof f2);
    __builtin_memcpy(w.fl[3] + g0, &f3, sizeof f3);
  }
  // the sub-step to the crossing on the piece being left (rk4_lane with k1 known), the
  // landing on the surface (land), the flip, and the rest of the step on the new piece
  // (field_piece, switching and switching_rate written out on scalars, the same arithmetic)
  struct T8 {
    v8d ksp, krp, E, dE, L1;
  };
  const v8d zero = {}, one = zero + 1.0;
  // terms_at (sine shape) at eight times at once, and at the step's own ends the tabulated
  // terms (as the TermCache of the lane-by-lane split holds them)
  auto terms8 = [&](v8d tau) __attribute__((always_inline)) {
    const double W = p[OMEGA];
    const v8d xx = W * (tau - ck.t);
    const v8d x2 = xx * xx;
    const v8d sx = xx * (1.0 + x2 * (-1.0 / 6 + x2 * (1.0 / 120 + x2 * (-1.0 / 5040 + x2 * (1.0 / 362880 + x2 * (-1.0 / 39916800))))));
    const v8d cx = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24 + x2 * (-1.0 / 720 + x2 * (1.0 / 40320 + x2 * (-1.0 / 3628800 +
                                                                                         x2 * (1.0 / 479001600))))));
    const v8d S0 = ck.sn[0] * cx + ck.cs[0] * sx, S1 = ck.sn[1] * cx + ck.cs[1] * sx;
    const v8d S2 = ck.sn[2] * cx + ck.cs[2] * sx, C2 = ck.cs[2] * cx - ck.sn[2] * sx;
    const v8d S3 = ck.sn[3] * cx + ck.cs[3] * sx, C3 = ck.cs[3] * cx - ck.sn[3] * sx;
    const v8d e_sp = p[ESA] * S2;
    const v8d de_sp = p[ESA] * W * C2;
    const v8d dde_sp = -p[ESA] * W * W * S2;
    const v8l at0 = tau == t, at1 = tau == te;
    const v8d ksp = p[KSM] + p[KSA] * S0, krp = p[KRM] + p[KRA] * S1, E = e_sp + p[ERA] * S3;
    const v8d dE = de_sp + p[ERA] * W * C3, L1 = p[MU_S] * p[F_D] + p[MU_C] * p[F_L] - dde_sp;
    T8 q;
    q.ksp = at1 ? zero + q2.ksp : (at0 ? zero + q0.ksp : ksp);
    q.krp = at1 ? zero + q2.krp : (at0 ? zero + q0.krp : krp);
    q.E = at1 ? zero + q2.E : (at0 ? zero + q0.E : E);
    q.dE = at1 ? zero + q2.dE : (at0 ? zero + q0.dE : dE);
    q.L1 = at1 ? zero + q2.L1 : (at0 ? zero + q0.L1 : L1);
    return q;
  };
  // the pieces of the field on given sides of the surfaces: the dead zone x - off where
  // `on`, 0 elsewhere (off = b on the upper side, -b on the lower: x - (-b) is x + b exactly)
  struct Pc {
    v8l on_sp, on_rp;
    v8d off_sp, off_rp;
  };
  auto pieces = [&](v8d s0, v8d s1, v8d s2, v8d s3) __attribute__((always_inline)) {
    Pc pc;  // (sides are +-1: never NaN)
    pc.on_sp = (s0 > 0.0) | (s1 < 0.0);
    pc.on_rp = (s2 > 0.0) | (s3 < 0.0);
    pc.off_sp = s0 > 0.0 ? zero + bsp : zero - bsp;
    pc.off_rp = s2 > 0.0 ? zero + brp : zero - brp;
    return pc;
  };
  // field_piece's velocity components on eight lanes
  auto piece = [&](const T8& q, v8d z0, v8d z1, v8d z2, v8d z3, const Pc& pc, v8d& v1, v8d& v3)
      __attribute__((always_inline)) {
    const v8d X = z2 - z0 - q.E, V = z3 - z1 - q.dE;
    const v8d fsp = pc.on_sp ? z0 - pc.off_sp : zero, frp = pc.on_rp ? X - pc.off_rp : zero;
    const v8d gsp = q.ksp * fsp + csp * z1, grp = q.krp * frp + crp * V;
    v1 = a2sp * gsp + a2rp * grp + q.L1;
    v3 = a4sp * gsp + a4rp * grp + L2;
  };
  // one RK4 step of length hs from time t0 on the pieces ``pc``, eight lanes: y -> o, with k the
  // field at (t0, y) (velocity rows k0 = y1, k2 = y3); returns the time terms at t0 + hs
  auto substep = [&](v8d t0, v8d hs, v8d y0, v8d y1, v8d y2, v8d y3, v8d k0, v8d k1, v8d k2, v8d k3, const Pc& pc,
                     v8d& o0, v8d& o1, v8d& o2, v8d& o3) __attribute__((always_inline)) {
    const v8d hm = 0.5 * hs;
    v8d b1, b3, c1, c3, d1, d3;
    const T8 qm = terms8(t0 + hm);
    const v8d u0 = y0 + hm * k0, u1 = y1 + hm * k1, u2 = y2 + hm * k2, u3 = y3 + hm * k3;
    piece(qm, u0, u1, u2, u3, pc, b1, b3);
    const v8d v0 = y0 + hm * u1, v1 = y1 + hm * b1, v2 = y2 + hm * u3, v3 = y3 + hm * b3;
    piece(qm, v0, v1, v2, v3, pc, c1, c3);
    const v8d z0 = y0 + hs * v1, z1 = y1 + hs * c1, z2 = y2 + hs * v3, z3 = y3 + hs * c3;
    const T8 qe = terms8(t0 + hs);
    piece(qe, z0, z1, z2, z3, pc, d1, d3);
    const v8d h6 = hs / 6.0;
    o0 = y0 + h6 * (k0 + 2.0 * (u1 + v1) + z1);
    o1 = y1 + h6 * (k1 + 2.0 * (b1 + c1) + d1);
    o2 = y2 + h6 * (k2 + 2.0 * (u3 + v3) + z3);
    o3 = y3 + h6 * (k3 + 2.0 * (b3 + c3) + d3);
    return qe;
  };
  auto store = [](double* dst, v8d v) { __builtin_memcpy(dst, &v, sizeof v); };
  const double habs = std::fabs(h);
  for (int g = 0; g < Kp; g += 8) {
    v8d sd0 = load8(w.sd[0] + g), sd1 = load8(w.sd[1] + g), sd2 = load8(w.sd[2] + g), sd3 = load8(w.sd[3] + g);
    const v8d y0 = load8(w.y[0] + g), y1 = load8(w.y[1] + g), y2 = load8(w.y[2] + g), y3 = load8(w.y[3] + g);
    const v8d a0 = load8(w.k1[0] + g), a1 = load8(w.k1[1] + g), a2 = load8(w.k1[2] + g), a3 = load8(w.k1[3] + g);
    v8d h1 = load8(w.th + g) * h;
    v8d m0, m1, m2, m3;
    const Pc pc1 = pieces(sd0, sd1, sd2, sd3);
    const T8 qe = substep(t + zero, h1, y0, y1, y2, y3, a0, a1, a2, a3, pc1, m0, m1, m2, m3);
    // land: one Newton correction along the piece being left
    {
      const v8d wh = load8(w.wh + g);
      v8d F1, F3;
      piece(qe, m0, m1, m2, m3, pc1, F1, F3);
      const v8d F0 = m1, F2 = m3;
      const v8d Xr = m2 - m0 - qe.E;
      const v8d r2 = F2 - F0 - qe.dE;
      const v8d rate = wh < 2.0 ? F0 : r2;
      const v8d Sa = m0 - bsp, Sb = m0 + bsp, Sc = Xr - brp, Sd = Xr + brp;
      const v8d Sw = wh == 0.0 ? Sa : (wh == 1.0 ? Sb : (wh == 2.0 ? Sc : Sd));
      const v8l rnz = rate != 0.0;
      const v8d dt = -Sw / (rnz ? rate : one);
      const v8d adt = dt < 0.0 ? -dt : dt;
      const v8l ok = (wh >= 0.0) & rnz & (dt - dt == 0.0) & (adt <= 0.25 * habs);
      const v8d n0 = m0 + F0 * dt, n1 = m1 + F1 * dt, n2 = m2 + F2 * dt, n3 = m3 + F3 * dt, nh = h1 + dt;
      m0 = ok ? n0 : m0;
      m1 = ok ? n1 : m1;
      m2 = ok ? n2 : m2;
      m3 = ok ? n3 : m3;
      h1 = ok ? nh : h1;
    }
    sd0 = sd0 * load8(w.fl[0] + g);
    sd1 = sd1 * load8(w.fl[1] + g);
    sd2 = sd2 * load8(w.fl[2] + g);
    sd3 = sd3 * load8(w.fl[3] + g);
    store(w.ym[0] + g, m0);
    store(w.ym[1] + g, m1);
    store(w.ym[2] + g, m2);
    store(w.ym[3] + g, m3);
    store(w.sd[0] + g, sd0);
    store(w.sd[1] + g, sd1);
    store(w.sd[2] + g, sd2);
    store(w.sd[3] + g, sd3);
    store(w.th + g, h1);
  }
  // the rest of the step (rk4_lane from the surface), in a second pass (shorter loop bodies:
  // the processor overlaps consecutive groups of eight)
  for (int g = 0; g < Kp; g += 8) {
    const v8d m0 = load8(w.ym[0] + g), m1 = load8(w.ym[1] + g), m2 = load8(w.ym[2] + g), m3 = load8(w.ym[3] + g);
    const v8d sd0 = load8(w.sd[0] + g), sd1 = load8(w.sd[1] + g), sd2 = load8(w.sd[2] + g), sd3 = load8(w.sd[3] + g);
    const v8d h1 = load8(w.th + g);
    const v8d tt = t + h1, hh = h - h1;
    v8d e1, e3;
    const T8 qa = terms8(tt);
    const Pc pc2 = pieces(sd0, sd1, sd2, sd3);
    piece(qa, m0, m1, m2, m3, pc2, e1, e3);
    const v8d K0 = m1, K1 = e1, K2 = m3, K3 = e3;
    v8d Y0, Y1, Y2, Y3;
    const T8 qc = substep(tt, hh, m0, m1, m2, m3, K0, K1, K2, K3, pc2, Y0, Y1, Y2, Y3);
    // a further event in the rest of the step? (the sign test of first_crossing)
    const v8d X1 = Y2 - Y0 - qc.E, X0 = m2 - m0 - qa.E;
    const v8d T1[4] = {Y0 - bsp, Y0 + bsp, X1 - brp, X1 + brp};
    const v8d T0[4] = {m0 - bsp, m0 + bsp, X0 - brp, X0 + brp};
    const v8d SD[4] = {sd0, sd1, sd2, sd3};
    v8l more = zero != zero;
    for (int i = 0; i < 4; ++i)
      more |= ((T1[i] >= 0.0 ? one : -one) != SD[i]) & (T1[i] - T1[i] == 0.0) & (T0[i] - T0[i] == 0.0);
    store(w.y1[0] + g, Y0);
    store(w.y1[1] + g, Y1);
    store(w.y1[2] + g, Y2);
    store(w.y1[3] + g, Y3);
    store(w.k1[0] + g, K0);
    store(w.k1[1] + g, K1);
    store(w.k1[2] + g, K2);
    store(w.k1[3] + g, K3);
    store(w.tt + g, tt);
    store(w.hh + g, hh);
    // the lanes done (written back to x1 here) and those that continue lane by lane (below);
    // lanes that are not finite keep their trial step
    const unsigned valid = (K - g >= 8 ? 0xffu : (1u << (K - g)) - 1u) & lane_bits(load8(w.fin + g) != 0.0);
    const unsigned cont = max_splits < 2 ? 0u : (max_splits > 2 ? valid : valid & lane_bits(more));
    w.cont[g / 8] = cont;
    w.done[g / 8] = valid & ~cont;
#if defined(__AVX512F__) && defined(__AVX512VL__)
    {
      const __mmask8 k = static_cast<__mmask8>(valid & ~cont);
      const __m256i at = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(ix + g));
      _mm512_mask_i32scatter_pd(x1[0], k, at, reinterpret_cast<__m512d>(Y0), 8);
      _mm512_mask_i32scatter_pd(x1[1], k, at, reinterpret_cast<__m512d>(Y1), 8);
      _mm512_mask_i32scatter_pd(x1[2], k, at, reinterpret_cast<__m512d>(Y2), 8);
      _mm512_mask_i32scatter_pd(x1[3], k, at, reinterpret_cast<__m512d>(Y3), 8);
    }
#endif
  }
  for (int g0 = 0; g0 < K; g0 += 8) {
#if !(defined(__AVX512F__) && defined(__AVX512VL__))
    for (unsigned d = w.done[g0 / 8]; d; d &= d - 1) {
      const int g = g0 + __builtin_ctz(d);
      for (int i = 0; i < 4; ++i) x1[i][idx[g]] = w.y1[i][g];
    }
#endif
    for (unsigned cm = w.cont[g0 / 8]; cm; cm &= cm - 1) {
      const int g = g0 + __builtin_ctz(cm);
      const int j = idx[g];
      // the rest of split_lane from its second event on, lane by lane
      TermCache tc;
      tc.t[0] = t;
      tc.q[0] = q0;
      tc.t[1] = te;
      tc.q[1] = q2;
      tc.n = 2;
      const double tt = w.tt[g], hh = w.hh[g];
      double Ym[4], Y1[4], K1[4], sides[4], S0[4], S1[4], out4[4];
      for (int i = 0; i < 4; ++i) {
        Ym[i] = w.ym[i][g];
        Y1[i] = w.y1[i][g];
        K1[i] = w.k1[i][g];
        sides[i] = w.sd[i][g];
      }
      switching(c, terms_cached(m, ck, tc, tt + hh).E, Y1, S1);
      switching(c, terms_cached(m, ck, tc, tt).E, Ym, S0);
      double th2;
      int which2;
      bool flips2[4];
      first_crossing(m, c, ck, tc, tt, hh, Ym, Y1, K1, S0, S1, sides, break_fraction(m, tt, hh), &th2, &which2,
                     flips2);
      const bool more = th2 < 1.0;
      if (!more && max_splits == 2) {
        for (int i = 0; i < 4; ++i) x1[i][j] = Y1[i];
        continue;
      }
      for (int i = 0; i < 4; ++i) flips2[i] = more && flips2[i];
      split_lane(m, c, ck, tc, tt, hh, Ym, K1, more ? th2 : 1.0, more ? which2 : -1, flips2, sides,
                 max_splits - 1, out4);
      for (int i = 0; i < 4; ++i) x1[i][j] = out4[i];
    }
  }
}

// Advance one block of lanes [a, b) by `periods` periods.
void run_block(const double* Y, double* out, int64_t n, int64_t a, int64_t b, const int32_t* lane_row,
               const std::vector<Model>& models, const std::vector<Coef>& coefs, const std::vector<const Table*>& tables,
               double t0, int periods, int steps, int max_splits, SplitScratch& w) {
  const int L = static_cast<int>(b - a);
  const int rows = static_cast<int>(models.size());
  alignas(64) double xa[4][kRow], xb[4][kRow];
  double (*x)[kRow] = xa;
  double (*x1)[kRow] = xb;
  int row[kBlock], lane[kBlock];  // lane j of the block is lane a + lane[j] of the batch
  for (int j = 0; j < L; ++j) {
    lane[j] = j;
    row[j] = lane_row ? row_index(lane_row[a + j], rows) : 0;
  }
  bool uniform = true;
  for (int j = 1; j < L; ++j) uniform &= row[j] == row[0];
  if (!uniform)  // lanes of several parameter rows: grouped by row, each group a run of the block
    std::stable_sort(lane, lane + L, [&](int p, int q) { return row[p] < row[q]; });
  int row_sorted[kBlock];
  for (int j = 0; j < L; ++j) row_sorted[j] = row[lane[j]];
  for (int j = 0; j < L; ++j) {
    row[j] = row_sorted[j];
    for (int i = 0; i < 4; ++i) x[i][j] = Y[i * n + a + lane[j]];
  }
  // runs of one parameter row: [run[k], run[k + 1])
  int run[kBlock + 1], nrun = 0;
  for (int j = 0; j < L; ++j)
    if (j == 0 || row[j] != row[j - 1]) run[nrun++] = j;
  run[nrun] = L;
  uint64_t need[kBlock / 64];
  int idx[kBlock];
  for (int per = 0; per < periods; ++per) {
    for (int s = 0; s < steps; ++s) {
      for (int k = 0; k < nrun; ++k) {
        const int j0 = run[k], j1 = run[k + 1];
        const int r = row[j0];
        const Model& m = models[r];
        const Coef& c = coefs[r];
        const Table& tb = *tables[r];
        const double h = m.T / steps;
        const double t = t0 + s * h;
        auto at = [j0](double (*v)[kRow]) { return reinterpret_cast<double (*)[kRow]>(&v[0][j0]); };
        trial_uniform(c, tb.stage[3 * s], tb.stage[3 * s + 1], tb.stage[3 * s + 2], h, j1 - j0, at(x), at(x1),
                      tb.E0[s], tb.E1[s], tb.thb[s] < 1.0, need);
        // lanes with an event (the set bits of need): split, all at once where the model
        // allows, else one by one
        int K = 0;
        for (int g = 0; 64 * g < j1 - j0; ++g)
          for (uint64_t mask = need[g]; mask; mask &= mask - 1) idx[K++] = j0 + 64 * g + __builtin_ctzll(mask);
        if (K == 0) continue;
        if (vector_split_ok(m, h)) {
          split_block(m, c, tb, s, t, h, max_splits, idx, K, x, x1, w);
          continue;
        }
        for (int g = 0; g < K; ++g) {
          const int j = idx[g];
          double y[4], y1[4], kl[4], S0[4], S1[4], sides[4], th, out4[4];
          int which;
          for (int i = 0; i < 4; ++i) {
            y[i] = x[i][j];
            y1[i] = x1[i][j];
          }
          if (tb.thb[s] >= 1.0 && !lane_finite(tb.E0[s], tb.E1[s], y, y1)) continue;  // the trial step stands
          TermCache tc;
          if (m.n_breaks == 0) {  // the step's own (unclipped) stage times are tabulated
            tc.t[0] = t;
            tc.q[0] = tb.stage[3 * s];
            tc.t[1] = t + h;
            tc.q[1] = tb.stage[3 * s + 2];
            tc.n = 2;
          }
          field(c, tb.stage[3 * s], y, kl);  // the trial step's first stage
          switching(c, tb.E0[s], y, S0);
          switching(c, tb.E1[s], y1, S1);
          for (int i = 0; i < 4; ++i) sides[i] = side(S0[i]);
          bool flips[4];
          first_crossing(m, c, tb.clock[s], tc, t, h, y, y1, kl, S0, S1, sides, tb.thb[s], &th, &which, flips);
          split_lane(m, c, tb.clock[s], tc, t, h, y, kl, th, which, flips, sides, max_splits, out4);
          for (int i = 0; i < 4; ++i) x1[i][j] = out4[i];
        }
      }
      std::swap(x, x1);
    }
  }
  for (int j = 0; j < L; ++j)
    for (int i = 0; i < 4; ++i) out[i * n + a + lane[j]] = x[i][j];
}

ffi::Error AdvanceImpl(ffi::Buffer<ffi::F64> Y, ffi::Buffer<ffi::F64> P, ffi::Buffer<ffi::S32> lane_row,
                       ffi::Buffer<ffi::F64> t0_buf, ffi::Buffer<ffi::S32> n_active_buf,
                       ffi::ResultBuffer<ffi::F64> out, int64_t periods, int64_t steps, int64_t max_splits,
                       int64_t shape) {
  // Y: (B..., 4, n); P: (B_P..., rows, NPARAM) with B_P in {1, B}; lane_row: (B_R..., n); t0: (B_T...,);
  // n_active: (B_A...,). Leading batch dimensions come from vmap (broadcast_all: every input
  // carries the whole batch, or none).
  // The output's leading dimensions are the batch; an input with a batch of one is shared.
  auto yd = Y.dimensions();
  const int64_t rank = yd.size();
  if (rank < 2 || yd[rank - 2] != 4) return ffi::Error::InvalidArgument("states must have shape (..., 4, n)");
  const int64_t n = yd[rank - 1];
  const int64_t batch = out->element_count() / std::max<int64_t>(4 * n, 1);
  const int64_t ybatch = Y.element_count() / std::max<int64_t>(4 * n, 1);
  auto pd = P.dimensions();
  const int64_t prank = pd.size();
  if (prank < 2 || pd[prank - 1] != NPARAM) return ffi::Error::InvalidArgument("parameter rows must have 24 entries");
  const int64_t rows = pd[prank - 2];
  if (rows < 1) return ffi::Error::InvalidArgument("at least one parameter row is needed");
  const int64_t pbatch = P.element_count() / (rows * NPARAM);
  const int64_t rbatch = lane_row.element_count() / std::max<int64_t>(n, 1);
  const int64_t tbatch = t0_buf.element_count();
  const int64_t abatch = n_active_buf.element_count();
  const double* y = Y.typed_data();
  const double* pp = P.typed_data();
  const int32_t* lr = lane_row.typed_data();
  const double* t0s = t0_buf.typed_data();
  const int32_t* nas = n_active_buf.typed_data();
  double* o = out->typed_data();
  for (int64_t bi = 0; bi < batch; ++bi) {
    const double* pb = pp + (pbatch == 1 ? 0 : bi) * rows * NPARAM;
    std::vector<Model> models(rows);
    std::vector<Coef> coefs(rows);
    std::vector<std::shared_ptr<const Table>> held(rows);  // the tables in use, kept alive
    std::vector<const Table*> tables(rows, nullptr);
    const double t0 = t0s[tbatch == 1 ? 0 : bi];
    const int32_t* rowp = lr + (rbatch == 1 ? 0 : bi) * n;
    const int64_t n_act = std::min<int64_t>(n, std::max<int32_t>(0, nas[abatch == 1 ? 0 : bi]));
    // only the rows of active lanes are tabulated (a pool of many rows holds few at a time)
    std::vector<unsigned char> used(rows, 0);
    for (int64_t j = 0; j < n_act; ++j) used[row_index(rowp[j], rows)] = 1;
    for (int64_t r = 0; r < rows; ++r) {
      models[r] = make_model(pb + r * NPARAM, static_cast<int>(shape));
      coefs[r] = coef(models[r]);
      if (used[r]) {
        held[r] = table_cache().get(models[r], table_key(pb + r * NPARAM, static_cast<int>(shape), t0, steps), t0,
                                    static_cast<int>(steps));
        tables[r] = held[r].get();
      }
    }
    const double* yb = y + (ybatch == 1 ? 0 : bi) * 4 * n;
    double* ob = o + bi * 4 * n;
    for (int64_t i = 0; i < 4; ++i)
      for (int64_t j = n_act; j < n; ++j) ob[i * n + j] = yb[i * n + j];
    // blocks of kBlock lanes; a pool too small to give every thread several of those is
    // cut into shorter blocks (at least kMinBlock lanes), so its last lanes keep every core
    // busy (a lane's result does not depend on the block it is in)
    const int64_t threads = std::max(1, omp_get_max_threads());
    int64_t bl = (n_act + threads * kBlocksPerThread - 1) / (threads * kBlocksPerThread);
    bl = std::min<int64_t>(kBlock, std::max<int64_t>(kMinBlock, (bl + 7) / 8 * 8));
    const int nb = static_cast<int>((n_act + bl - 1) / bl);
#pragma omp parallel
    {
      std::unique_ptr<SplitScratch> scratch(new SplitScratch);
#pragma omp for schedule(dynamic, 1)
      for (int blk = 0; blk < nb; ++blk) {
        const int64_t a = static_cast<int64_t>(blk) * bl;
        const int64_t b = std::min<int64_t>(a + bl, n_act);
        run_block(yb, ob, n, a, b, rowp, models, coefs, tables, t0, static_cast<int>(periods),
                  static_cast<int>(steps), static_cast<int>(max_splits), *scratch);
      }
    }
  }
  return ffi::Error::Success();
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(JaxgearReducedAdvance, AdvanceImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::S32>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::S32>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Attr<int64_t>("periods")
                                  .Attr<int64_t>("steps")
                                  .Attr<int64_t>("max_splits")
                                  .Attr<int64_t>("shape"));
