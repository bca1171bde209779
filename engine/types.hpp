#pragma once
// Basic types shared by the whole engine. SI units everywhere; angles in radians.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>

namespace demcal::engine {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

constexpr double kPi = 3.14159265358979323846;

inline double deg_to_rad(double deg) { return deg * kPi / 180.0; }
inline double rad_to_deg(double rad) { return rad * 180.0 / kPi; }

inline double sphere_volume(double radius) { return 4.0 / 3.0 * kPi * radius * radius * radius; }

}  // namespace demcal::engine
