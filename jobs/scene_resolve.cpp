#include "scene_resolve.hpp"

#include "job_error.hpp"
#include "material_params.hpp"
#include "scene_registry.hpp"

#include <algorithm>
#include <iomanip>
#include <sstream>

namespace demcal::jobs {

void resolve_time_step(nlohmann::json& p, const std::string& section, double default_factor) {
  if (p.contains("dt") && p.contains("dt_factor")) throw JobError(section + ".dt", "give dt or dt_factor, not both");
  if (!p.contains("dt")) p.emplace("dt_factor", p.value("dt_factor", default_factor));
}

void erase_default(nlohmann::json& p, const std::string& key, const nlohmann::json& value) {
  if (p.contains(key) && p[key] == value) p.erase(key);
}

std::ostream& next_note(std::ostringstream& os, int precision) {
  if (os.tellp() > 0) os << "; ";
  os.precision(precision);
  return os;
}

std::string grading_cut_note(const engine::Grading& g) {
  const auto [below, above] = g.mass_cut();
  if (below + above <= 0.2) return "";
  std::ostringstream os;
  os << std::setprecision(3) << "material.diameter min and max (" << g.d_min << ", " << g.d_max
     << " m) keep " << 100.0 * (1.0 - below - above) << "% of the grading curve's mass (" << 100.0 * below
     << "% is finer than min, " << 100.0 * above << "% coarser than max): the sample is the curve's middle, not "
     << "the sand; a wider range keeps more, at the price of a smaller step (the smallest grain sets it)";
  return os.str();
}

void resolve_diameters(nlohmann::json& p) {
  if (p.contains("grading")) {
    // A sieve chart's points are joined by straight lines in log d unless the job says d.
    if (!p.contains("size_distribution")) p["size_distribution"] = engine::to_string(engine::SizeDistribution::log_uniform_mass);
    if (p["size_distribution"] == kImpliedUniformSizes.second)
      throw JobError("material.diameter.distribution",
                     "\"uniform\" draws by number; a grading curve gives mass, so its points are joined by "
                     "\"log_uniform_mass\" (straight in log d, the default with a curve) or \"uniform_mass\" (straight in d)");
    // Without min and max the grains run from the largest size with nothing finer to
    // the smallest with everything finer (a sieve report lists 0% at several fine
    // sieves; the smallest grain sets the time step). With them the curve is cut to
    // [min, max] (a wide measured grading, scalped to what a simulation affords).
    const nlohmann::json& d = p["grading"]["d"];
    const nlohmann::json& pf = p["grading"]["percent_finer"];
    std::size_t lo = 0, hi = d.size() - 1;
    while (lo + 1 < d.size() && pf[lo + 1].get<double>() == 0.0) ++lo;
    while (hi > lo + 1 && pf[hi - 1].get<double>() == 100.0) --hi;
    const bool min_given = p.contains("d_min"), max_given = p.contains("d_max");
    if (!min_given) p["d_min"] = d[lo];
    if (!max_given) p["d_max"] = d[hi];
    if (min_given != max_given && p["d_min"].get<double>() >= p["d_max"].get<double>())
      throw JobError(min_given ? "material.diameter.min" : "material.diameter.max",
                     (min_given ? "must be below " : "must exceed ") + std::string("the curve's ") +
                         (min_given ? "smallest size with everything finer, " + p["d_max"].dump()
                                    : "largest size with nothing finer, " + p["d_min"].dump()) +
                         " m; got " + p[min_given ? "d_min" : "d_max"].dump());
  } else {
    const engine::Material m;
    if (!p.contains("d_min")) p["d_min"] = m.d_min;
    if (!p.contains("d_max")) p["d_max"] = m.d_max;
  }
  if (p["d_min"].get<double>() > p["d_max"].get<double>())
    throw JobError("material.diameter", "min (" + p["d_min"].dump() + ") must not exceed max (" + p["d_max"].dump() + ")");
  erase_default(p, kImpliedUniformSizes.first, kImpliedUniformSizes.second);
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
