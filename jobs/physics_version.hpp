#pragma once
#include <string>

namespace demcal::jobs {

// Part of every task's content key, per scene. Bump a scene's version when engine
// physics changes that scene's results, so that work stored under the old physics is
// not reused as if it were current, and work a change does not touch is kept.
//   1: the first (every scene).
//   2 (every scene): the unbalanced-force ratio reads the net force before local
//      damping, so damped preparation stages (triaxial) end when the undamped
//      imbalance passes; the repose slope is fitted over the deposit up to its
//      front, not past it.
//   3 (triaxial): the dense preparation's frictionless stages step at the same
//      fraction of their own critical step as the material's full law takes of
//      its (about 1.96x dt for the seed's material, whatever theta and eta;
//      triaxial.frictionless_dt_scale), the unloading ramp lasting as long in
//      simulated time as before.
// Not bumped for changes to what is read from an unchanged trajectory, which would
// throw away hours of stored work to move a reading by round-off: on 2026-11-29 the
// critical-state window took in a row on its edge (one of ~100: phi_cv moved by
// 0.009 deg on the 2,000-grain validation run's stored series), a shear shorter than the dilatancy
// window left max_dilatancy_deg unmeasured (it read -90), and a repose heap at rest
// by its profile took its time to rest from when it held still. Results stored
// before keep their readings (docs/validation.md says which).
constexpr int kTriaxialPhysicsVersion = 3;
constexpr int kOtherPhysicsVersion = 2;  // collision, repose

inline int physics_version(const std::string& scene) {
  return scene == "triaxial" ? kTriaxialPhysicsVersion : kOtherPhysicsVersion;
}

}  // namespace demcal::jobs
