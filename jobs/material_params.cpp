#include "material_params.hpp"

namespace demcal::jobs {

namespace {
std::vector<std::string> distributions() {
  std::vector<std::string> out;
  for (engine::SizeDistribution s : engine::kSizeDistributions) out.emplace_back(engine::to_string(s));
  return out;
}
}  // namespace

std::vector<ParamSpec> material_params() {
  const engine::Material d;  // the engine's defaults are the job file's defaults
  return {
      real_param("material", "kn", "kn", d.kn).above(0),
      real_param("material", "ks", "ks", d.ks).above(0),
      real_param("material", "density", "density", d.density).above(0),
      real_param("material", "b", "b", d.rolling_b).above(0),
      real_param("material", "theta_deg", "theta_deg", 0.0).at_least(0).below(90),
      real_param("material", "eta", "eta", d.rolling_eta).at_least(0),
      // Their defaults are set with the grading (resolve_diameters): a measured curve
      // without them runs from its largest size at 0% finer to its smallest at 100%.
      real_param("material", "diameter.min", "d_min", nullptr).above(0).at_most(1.0),
      real_param("material", "diameter.max", "d_max", nullptr).above(0).at_most(1.0),
      // No fallback: a job that leaves the grading out keeps the task keys it had
      // before the field existed (uniform by number).
      choice_param("material", "diameter.distribution", "size_distribution", distributions(), nullptr),
      curve_param("material", "diameter.grading", "grading"),
  };
}

engine::Material material_from(const nlohmann::json& p) {
  engine::Material m;
  m.kn = p.at("kn").get<double>();
  m.ks = p.at("ks").get<double>();
  m.density = p.at("density").get<double>();
  m.rolling_b = p.at("b").get<double>();
  m.friction_angle = engine::deg_to_rad(p.at("theta_deg").get<double>());
  m.rolling_eta = p.at("eta").get<double>();
  m.d_min = p.at("d_min").get<double>();
  m.d_max = p.at("d_max").get<double>();
  // The choice is checked against the parameter's list before this runs.
  if (p.contains("size_distribution"))
    engine::parse_size_distribution(p.at("size_distribution").get<std::string>(), m.size_distribution);
  if (p.contains("grading")) {
    m.grading_curve.d = p.at("grading").at("d").get<std::vector<double>>();
    for (const auto& x : p.at("grading").at("percent_finer")) m.grading_curve.finer.push_back(x.get<double>() / 100.0);
  }
  return m;
}

std::string job_path_of(const std::string& field, const std::string& section) {
  if (field == "material.friction_angle") return "material.theta_deg";
  if (field.rfind("numerics.", 0) == 0) return section + "." + field.substr(9);
  return field;
}

}  // namespace demcal::jobs
