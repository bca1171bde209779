#pragma once
// A rigid planar wall: infinite plane through `point` with unit `normal` pointing
// into the domain. Walls may move with a prescribed velocity (servo control sets it).
#include "types.hpp"

#include <string>

namespace demcal::engine {

struct Wall {
  std::string name;
  Vec3 point = Vec3::Zero();
  Vec3 normal = Vec3::UnitZ();
  Vec3 velocity = Vec3::Zero();
  bool frictional = false;  // false: smooth wall (normal force only, as the seed's triaxial walls)
  bool rolling = false;     // rolling resistance against this wall (needs frictional)
  bool active = true;       // an inactive wall (a removed gate) exerts nothing

  // Accumulated each step: force the particles exert on the wall, contact count
  // and the summed normal stiffness of its contacts (for servo gains).
  Vec3 force = Vec3::Zero();
  int contacts = 0;
  double stiffness = 0.0;

  double distance(const Vec3& x) const { return (x - point).dot(normal); }
};

}  // namespace demcal::engine
