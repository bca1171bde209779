#include "scene_resolve.hpp"

#include "job_error.hpp"
#include "material_params.hpp"

#include <algorithm>

namespace demcal::jobs {

void resolve_time_step(nlohmann::json& p, const std::string& section, double default_factor) {
  if (p.contains("dt") && p.contains("dt_factor")) throw JobError(section + ".dt", "give dt or dt_factor, not both");
  if (!p.contains("dt")) p.emplace("dt_factor", p.value("dt_factor", default_factor));
}

void resolve_diameters(nlohmann::json& p) {
  if (p.contains("grading")) {
    // A sieve chart's points are joined by straight lines in log d unless the job says d.
    if (!p.contains("size_distribution")) p["size_distribution"] = engine::to_string(engine::SizeDistribution::log_uniform_mass);
    if (p["size_distribution"] == "uniform")
      throw JobError("material.diameter.distribution",
                     "\"uniform\" draws by number; a grading curve gives mass, so its points are joined by "
                     "\"log_uniform_mass\" (straight in log d, the default with a curve) or \"uniform_mass\" (straight in d)");
    // Without min and max the curve runs from its first size to its last; with them it
    // is cut to [min, max] (a wide measured grading, scalped to what a simulation affords).
    const nlohmann::json& d = p["grading"]["d"];
    if (!p.contains("d_min")) p["d_min"] = d.front();
    if (!p.contains("d_max")) p["d_max"] = d.back();
  } else {
    const engine::Material m;
    if (!p.contains("d_min")) p["d_min"] = m.d_min;
    if (!p.contains("d_max")) p["d_max"] = m.d_max;
  }
  if (p["d_min"].get<double>() > p["d_max"].get<double>())
    throw JobError("material.diameter", "min (" + p["d_min"].dump() + ") must not exceed max (" + p["d_max"].dump() + ")");
  if (p.contains("size_distribution") && p["size_distribution"] == "uniform") p.erase("size_distribution");
  if (p.contains("grading"))
    if (const std::string why = material_from(p).grading().problem(); !why.empty())
      throw JobError("material.diameter.grading", why);
}

void throw_as_job_error(const engine::ConfigError& e, const std::string& job_path) {
  // what() is "<field>: <reason>".
  std::string reason = e.what();
  reason = reason.substr(std::min(reason.size(), e.field().size() + 2));
  throw JobError(job_path, reason);
}

}  // namespace demcal::jobs
