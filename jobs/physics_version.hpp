#pragma once

namespace demcal::jobs {

// Part of every task's content key. Bump when engine physics changes results, so
// that work stored under the old physics is not reused as if it were current.
//   1: the first.
//   2: the unbalanced-force ratio reads the net force before local damping, so
//      damped preparation stages (triaxial) end when the undamped imbalance passes;
//      the repose slope is fitted over the deposit up to its front, not past it.
constexpr int kPhysicsVersion = 2;

}  // namespace demcal::jobs
