#pragma once
// The seed's pair contact law (contact_law.hpp, Eqs. 2.3-2.6) evaluated over a batch
// of touching pairs stored lane by lane, so that the compiler turns the arithmetic
// into SIMD across contacts. Per contact the law is ~250 flops with two
// data-dependent caps; contact by contact in scalar code that is ~430 instructions,
// almost all of the engine's time. Laid out as one array per scalar and with the caps
// written as selects, the same arithmetic runs 2 (SSE2) or 4 (AVX2) contacts at a
// time. The pair loop (world.cpp) packs touching pairs into a batch, calls
// `pair_batch_law`, then scatters forces and torques and writes the history back.
// test_contact checks this kernel against `apply_contact_law` contact by contact.
#include "material.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::engine {

constexpr int kPairBatch = 64;  // lanes per batch: ~18 KB, stays in L1

struct alignas(64) PairBatch {
  int count = 0;
  int i[kPairBatch], j[kPairBatch], e[kPairBatch];  // pair and list entry of each lane
  // Inputs: centre offset x_j - x_i (minimum image), its squared length, radii,
  // v_i - v_j, spins of both grains.
  alignas(64) double dx[kPairBatch], dy[kPairBatch], dz[kPairBatch], d2[kPairBatch];
  alignas(64) double ri[kPairBatch], rj[kPairBatch];
  alignas(64) double vx[kPairBatch], vy[kPairBatch], vz[kPairBatch];
  alignas(64) double wix[kPairBatch], wiy[kPairBatch], wiz[kPairBatch];
  alignas(64) double wjx[kPairBatch], wjy[kPairBatch], wjz[kPairBatch];
  // History in, updated history out: tangential spring force and rolling moment on i.
  alignas(64) double fsx[kPairBatch], fsy[kPairBatch], fsz[kPairBatch];
  alignas(64) double mrx[kPairBatch], mry[kPairBatch], mrz[kPairBatch];
  // Outputs: force on i (j gets minus it), torques on i and on j, overlap.
  alignas(64) double fx[kPairBatch], fy[kPairBatch], fz[kPairBatch];
  alignas(64) double tix[kPairBatch], tiy[kPairBatch], tiz[kPairBatch];
  alignas(64) double tjx[kPairBatch], tjy[kPairBatch], tjz[kPairBatch];
  alignas(64) double delta[kPairBatch];  // overlap
};

namespace batch_detail {

// Removes the component along the unit normal n from (x, y, z) and returns it.
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
inline double drop_normal(double& x, double& y, double& z, double nx, double ny, double nz) {
  const double c = x * nx + y * ny + z * nz;
  x -= c * nx;
  y -= c * ny;
  z -= c * nz;
  return c;
}

// carry_into_tangent_plane of contact_law.hpp on one lane: twist with the pair,
// drop the normal component, restore the magnitude.
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
inline void carry(double& hx, double& hy, double& hz, double nx, double ny, double nz, double twist) {
  const double mag2 = hx * hx + hy * hy + hz * hz;
  double x = hx + twist * (ny * hz - nz * hy);
  double y = hy + twist * (nz * hx - nx * hz);
  double z = hz + twist * (nx * hy - ny * hx);
  drop_normal(x, y, z, nx, ny, nz);
  const double now2 = x * x + y * y + z * z;
  // The pair turns by a tiny angle per step, so q = mag2/now2 - 1 is ~1e-10:
  // sqrt(1 + q) = 1 + q/2 - q^2/8 to O(q^3) needs one division and no root. Even
  // at 0.1 rad per step (far past stability) the magnitude is kept to 1e-7.
  // Written without branches so that the loop vectorises; the clamp keeps a history
  // lying along the normal (now2 = 0, never met in practice) finite.
  const double q = std::min(mag2 / std::max(now2, 1e-300) - 1.0, 1.0);
  const double s = 1.0 + q * (0.5 - 0.125 * q);
  hx = x * s;
  hy = y * s;
  hz = z * s;
}

// Factor that brings a vector of squared length h2 down to length `cap` if it is
// longer: cap/sqrt(max(h2, cap^2)) is exactly 1 below the cap (sqrt(c*c) == c in
// IEEE arithmetic) and 0 for a zero cap. A select, not a branch: it vectorises.
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
inline double cap_scale(double h2, double cap) {
  return cap / std::sqrt(std::max(std::max(h2, cap * cap), 1e-300));
}

// One step of an incremental spring with a cap, on one lane: h -= k_dt * u, then
// brought down to length `cap` if longer (Coulomb for the tangential force, the
// plastic moment for the rolling one).
#if defined(__GNUC__)
__attribute__((always_inline))
#endif
inline void spring_step(double& hx, double& hy, double& hz, double k_dt, double ux, double uy, double uz,
                        double cap) {
  hx -= k_dt * ux;
  hy -= k_dt * uy;
  hz -= k_dt * uz;
  const double s = cap_scale(hx * hx + hy * hy + hz * hz, cap);
  hx *= s;
  hy *= s;
  hz *= s;
}

}  // namespace batch_detail

// Applies the law to lanes [0, b.count). Friction: Ks > 0 and tan(theta) used;
// Rolling: the rolling spring is active; Twist: it also resists relative twist.
// Without friction only the force along the normal and the overlap are written (no
// torques, no history: the caller neither reads nor stores them).
template <bool Friction, bool Rolling, bool Twist>
void pair_batch_law(const ContactParams& p, double dt, PairBatch& b) {
  static_assert(Friction || !Rolling, "rolling resistance needs the tangential spring");
  const int n = b.count;
  const double kn = p.kn, ksdt = p.ks * dt, tan_theta = p.tan_theta;
  const double krdt = p.b * p.ks * dt, eta = p.eta, half_dt = 0.5 * dt;
#pragma omp simd
  for (int l = 0; l < n; ++l) {
    const double dist = std::sqrt(b.d2[l]);
    const double inv = 1.0 / dist;
    const double nx = b.dx[l] * inv, ny = b.dy[l] * inv, nz = b.dz[l] * inv;
    const double ri = b.ri[l], rj = b.rj[l];
    const double rsum = ri + rj;
    const double delta = rsum - dist;
    const double ai = ri - 0.5 * delta, aj = rj - 0.5 * delta;
    const double fn = kn * delta;
    b.delta[l] = delta;
    double fx = -fn * nx, fy = -fn * ny, fz = -fn * nz;
    double tix = 0.0, tiy = 0.0, tiz = 0.0, tjx = 0.0, tjy = 0.0, tjz = 0.0;
    if constexpr (Friction) {
      const double wix = b.wix[l], wiy = b.wiy[l], wiz = b.wiz[l];
      const double wjx = b.wjx[l], wjy = b.wjy[l], wjz = b.wjz[l];
      const double twist = half_dt * ((wix + wjx) * nx + (wiy + wjy) * ny + (wiz + wjz) * nz);
      // Surface velocity of i relative to j at the contact point, tangential part.
      const double sx = ai * wix + aj * wjx, sy = ai * wiy + aj * wjy, sz = ai * wiz + aj * wjz;
      double vx = b.vx[l] + (sy * nz - sz * ny);
      double vy = b.vy[l] + (sz * nx - sx * nz);
      double vz = b.vz[l] + (sx * ny - sy * nx);
      batch_detail::drop_normal(vx, vy, vz, nx, ny, nz);
      double hx = b.fsx[l], hy = b.fsy[l], hz = b.fsz[l];
      batch_detail::carry(hx, hy, hz, nx, ny, nz, twist);
      batch_detail::spring_step(hx, hy, hz, ksdt, vx, vy, vz, fn * tan_theta);
      b.fsx[l] = hx;
      b.fsy[l] = hy;
      b.fsz[l] = hz;
      fx += hx;
      fy += hy;
      fz += hz;
      const double cx = ny * hz - nz * hy, cy = nz * hx - nx * hz, cz = nx * hy - ny * hx;
      tix = ai * cx;
      tiy = ai * cy;
      tiz = ai * cz;
      tjx = aj * cx;
      tjy = aj * cy;
      tjz = aj * cz;
      if constexpr (Rolling) {
        double ux = wix - wjx, uy = wiy - wjy, uz = wiz - wjz;
        double mx = b.mrx[l], my = b.mry[l], mz = b.mrz[l];
        if constexpr (Twist) {
          const double mt = batch_detail::drop_normal(mx, my, mz, nx, ny, nz);
          batch_detail::carry(mx, my, mz, nx, ny, nz, twist);
          mx += mt * nx;
          my += mt * ny;
          mz += mt * nz;
        } else {
          batch_detail::carry(mx, my, mz, nx, ny, nz, twist);
          batch_detail::drop_normal(ux, uy, uz, nx, ny, nz);
        }
        const double r = 0.5 * rsum;
        batch_detail::spring_step(mx, my, mz, krdt * r * r, ux, uy, uz, eta * r * fn);
        b.mrx[l] = mx;
        b.mry[l] = my;
        b.mrz[l] = mz;
        tix += mx;
        tiy += my;
        tiz += mz;
        tjx -= mx;
        tjy -= my;
        tjz -= mz;
      } else {
        b.mrx[l] = 0.0;
        b.mry[l] = 0.0;
        b.mrz[l] = 0.0;
      }
    }
    b.fx[l] = fx;
    b.fy[l] = fy;
    b.fz[l] = fz;
    if constexpr (Friction) {
      b.tix[l] = tix;
      b.tiy[l] = tiy;
      b.tiz[l] = tiz;
      b.tjx[l] = tjx;
      b.tjy[l] = tjy;
      b.tjz[l] = tjz;
    }
  }
}

// Runs the kernel variant the parameters call for.
inline void pair_batch_law(const ContactParams& p, double dt, PairBatch& b) {
  const bool friction = p.ks > 0.0;
  if (!friction)
    pair_batch_law<false, false, false>(p, dt, b);
  else if (!p.rolling())
    pair_batch_law<true, false, false>(p, dt, b);
  else if (p.twist)
    pair_batch_law<true, true, true>(p, dt, b);
  else
    pair_batch_law<true, true, false>(p, dt, b);
}

}  // namespace demcal::engine
