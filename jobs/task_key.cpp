#include "task_key.hpp"

#include "physics_version.hpp"

#include <cstdint>
#include <cstdio>

namespace demcal::jobs {
namespace {
// FNV-1a, 64 bit, from a given basis. Two independent bases give 128 bits: not a
// cryptographic hash, but keys are never adversarial and 2^-64 collisions suffice.
std::uint64_t fnv1a(const std::string& s, std::uint64_t h) {
  for (unsigned char c : s) {
    h ^= c;
    h *= 0x100000001b3ULL;
  }
  return h;
}
}  // namespace

std::string task_key(const std::string& scene, const nlohmann::json& params, bool snapshots) {
  const std::string text = scene + "\n" + params.dump() + "\nphysics=" + std::to_string(physics_version(scene)) +
                           (snapshots ? "\nsnapshots" : "");
  char buf[40];
  std::snprintf(buf, sizeof buf, "%016llx%016llx", static_cast<unsigned long long>(fnv1a(text, 0xcbf29ce484222325ULL)),
                static_cast<unsigned long long>(fnv1a(text, 0x84222325cbf29ce4ULL)));
  return buf;
}

}  // namespace demcal::jobs
