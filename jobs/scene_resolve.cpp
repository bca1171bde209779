#include "scene_resolve.hpp"

#include "job_error.hpp"

#include <algorithm>

namespace demcal::jobs {

void resolve_time_step(nlohmann::json& p, const std::string& section, double default_factor) {
  if (p.contains("dt") && p.contains("dt_factor")) throw JobError(section + ".dt", "give dt or dt_factor, not both");
  if (!p.contains("dt")) p.emplace("dt_factor", p.value("dt_factor", default_factor));
}

void resolve_diameters(nlohmann::json& p) {
  if (p["d_min"].get<double>() > p["d_max"].get<double>())
    throw JobError("material.diameter", "min (" + p["d_min"].dump() + ") must not exceed max (" + p["d_max"].dump() + ")");
  if (p.contains("size_distribution") && p["size_distribution"] == "uniform") p.erase("size_distribution");
}

void throw_as_job_error(const engine::ConfigError& e, const std::string& job_path) {
  // what() is "<field>: <reason>".
  std::string reason = e.what();
  reason = reason.substr(std::min(reason.size(), e.field().size() + 2));
  throw JobError(job_path, reason);
}

}  // namespace demcal::jobs
