#pragma once
// A rigid planar wall: infinite plane through `point` with unit `normal` pointing
// into the domain. Walls may move with a prescribed velocity (servo control sets it).
#include "types.hpp"

#include <string>
#include <vector>

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

// Six smooth walls enclosing the box [lo, hi], in the order x-, x+, y-, y+, z-, z+
// (index = 2 * axis + side), normals pointing inwards.
inline std::vector<Wall> box_walls(const Vec3& lo, const Vec3& hi) {
  std::vector<Wall> walls;
  const char* names[3][2] = {{"x-", "x+"}, {"y-", "y+"}, {"z-", "z+"}};
  for (int a = 0; a < 3; ++a) {
    for (int s = 0; s < 2; ++s) {
      Wall w;
      w.name = names[a][s];
      w.point = s == 0 ? lo : hi;
      w.normal = (s == 0 ? 1.0 : -1.0) * Vec3::Unit(a);
      walls.push_back(w);
    }
  }
  return walls;
}

}  // namespace demcal::engine
