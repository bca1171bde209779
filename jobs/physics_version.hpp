#pragma once

namespace demcal::jobs {

// Part of every task's content key. Bump when engine physics changes results, so
// that work stored under the old physics is not reused as if it were current.
constexpr int kPhysicsVersion = 1;

}  // namespace demcal::jobs
