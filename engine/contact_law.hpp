#pragma once
// The seed's contact law (Eqs. 2.3-2.6), one contact at a time: grain-wall contacts
// run it, and it is the reference the batched pair kernel (contact_batch.hpp, what
// grain-grain contacts run) is tested against lane by lane.
//
//  normal      Fn = Kn * delta along the contact normal, repulsive only;
//  tangential  incremental spring Fs kept in the contact history, carried into the
//              current tangent plane each step (tilt and twist of the pair), then
//              Fs += -Ks * v_t * dt and capped at |Fn| tan(theta) (Coulomb sliding);
//  rolling     incremental moment Mr, Mr += -Kr * w_roll * dt with Kr = b Ks r^2,
//              capped at Mp = eta r |Fn|; +Mr on sphere i, -Mr on sphere j.
// No damping: the law is elastic-plastic and dissipates only by sliding and
// plastic rolling.
#include "material.hpp"
#include "types.hpp"

#include <cmath>

namespace demcal::engine {

// Geometry and kinematics of one contact, as seen from sphere i.
struct ContactKinematics {
  Vec3 n;          // unit normal from i towards j (or towards the wall)
  double delta;    // overlap > 0
  Vec3 v_rel;      // velocity of i's surface relative to j's at the contact point
  Vec3 w_rel;      // w_i - w_j
  double spin_n;   // mean spin of the pair about n: rotates the history with the pair
  double r_roll;   // rolling radius: (Ri + Rj)/2 for a pair, R for a wall
};

// What one contact produces. Force and moment act on i; the caller applies the
// reaction to j (or to the wall).
struct ContactResponse {
  Vec3 force;        // total force on i
  Vec3 fs;           // tangential part of it (torque arm is the caller's)
  double fn;         // |normal force|
  bool sliding;      // the Coulomb cap was active
  bool rolling_slip; // the plastic moment cap was active
};

// Carries a history vector into the current tangent plane: twist with the pair's
// spin about n, drop the normal component, keep the magnitude (no spurious work).
#if defined(__GNUC__)
#define DEMCAL_HOT inline __attribute__((always_inline))
#else
#define DEMCAL_HOT inline
#endif

DEMCAL_HOT void carry_into_tangent_plane(Vec3& h, const Vec3& n, double twist_angle) {
  const double mag2 = h.squaredNorm();
  if (mag2 == 0.0) return;
  h += twist_angle * n.cross(h);
  h -= h.dot(n) * n;
  const double now2 = h.squaredNorm();
  // The normal turns by a tiny angle per step, so now2/mag2 = 1 - e with e ~ 1e-10:
  // sqrt(1/(1-e)) = 1 + e/2 to O(e^2), one division instead of division and root.
  const double e = 1.0 - now2 / mag2;
  if (std::abs(e) < 1e-6)
    h *= 1.0 + 0.5 * e;
  else if (now2 > 0.0)
    h *= std::sqrt(mag2 / now2);
}

// Applies the law; `fs` and `mr` are the contact's history, updated in place.
DEMCAL_HOT ContactResponse apply_contact_law(const ContactParams& p, double dt, const ContactKinematics& k,
                                         Vec3& fs, Vec3& mr, bool frictional, bool rolling) {
  ContactResponse out;
  out.fn = p.kn * k.delta;
  out.sliding = false;
  out.rolling_slip = false;
  const double twist = k.spin_n * dt;

  if (frictional && p.ks > 0.0) {
    carry_into_tangent_plane(fs, k.n, twist);
    const Vec3 vt = k.v_rel - k.v_rel.dot(k.n) * k.n;
    fs -= (p.ks * dt) * vt;
    const double cap = out.fn * p.tan_theta;
    const double fs2 = fs.squaredNorm();
    if (fs2 > cap * cap) {
      out.sliding = true;
      fs *= (fs2 > 0.0 ? cap / std::sqrt(fs2) : 0.0);
    }
  } else {
    fs.setZero();
  }

  if (rolling && frictional && p.rolling()) {
    Vec3 w_roll;
    if (p.twist) {
      // Keep the twisting part of the moment along the current normal; carry the
      // rolling part like the tangential force.
      const double m_twist = mr.dot(k.n);
      mr -= m_twist * k.n;
      carry_into_tangent_plane(mr, k.n, twist);
      mr += m_twist * k.n;
      w_roll = k.w_rel;
    } else {
      carry_into_tangent_plane(mr, k.n, twist);
      w_roll = k.w_rel - k.w_rel.dot(k.n) * k.n;
    }
    const double kr = p.b * p.ks * k.r_roll * k.r_roll;
    mr -= (kr * dt) * w_roll;
    const double cap = p.eta * k.r_roll * out.fn;
    const double mr2 = mr.squaredNorm();
    if (mr2 > cap * cap) {
      out.rolling_slip = true;
      mr *= (mr2 > 0.0 ? cap / std::sqrt(mr2) : 0.0);
    }
  } else {
    mr.setZero();
  }

  out.fs = fs;
  out.force = fs - out.fn * k.n;
  return out;
}

// Elastic energy stored in one contact's springs.
inline double contact_elastic_energy(const ContactParams& p, double delta, const Vec3& fs, const Vec3& mr,
                                     double r_roll) {
  double e = 0.5 * p.kn * delta * delta;
  if (p.ks > 0.0) e += 0.5 * fs.squaredNorm() / p.ks;
  const double kr = p.b * p.ks * r_roll * r_roll;
  if (kr > 0.0) e += 0.5 * mr.squaredNorm() / kr;
  return e;
}

}  // namespace demcal::engine
