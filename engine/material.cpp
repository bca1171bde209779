#include "material.hpp"

#include "errors.hpp"
#include "observer.hpp"

#include <cmath>

namespace demcal::engine {
namespace {
void positive(double v, const char* field) {
  if (!std::isfinite(v) || v <= 0.0) throw ConfigError(field, "must be a finite number > 0");
}
void non_negative(double v, const char* field) {
  if (!std::isfinite(v) || v < 0.0) throw ConfigError(field, "must be a finite number >= 0");
}
}  // namespace

void Material::validate() const {
  positive(kn, "material.kn");
  // Ks = 0 or b = 0 would switch friction or rolling resistance off whatever theta
  // and eta say, and every result would still read as theirs.
  positive(ks, "material.ks");
  positive(density, "material.density");
  if (!std::isfinite(friction_angle) || friction_angle < 0.0 || friction_angle >= kPi / 2)
    throw ConfigError("material.friction_angle", "must lie in [0, 90) degrees");
  positive(rolling_b, "material.b");
  non_negative(rolling_eta, "material.eta");
  positive(d_min, "material.diameter.min");
  positive(d_max, "material.diameter.max");
  if (d_min > d_max) throw ConfigError("material.diameter", "min must not exceed max");
  if (const std::string p = grading().problem(); !p.empty()) throw ConfigError("material.diameter.grading", p);
}

std::size_t Series::column(const std::string& col) const {
  for (std::size_t i = 0; i < columns.size(); ++i)
    if (columns[i] == col) return i;
  throw std::out_of_range("series " + name + " has no column " + col);
}

}  // namespace demcal::engine
