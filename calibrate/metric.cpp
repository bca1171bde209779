#include "metric.hpp"

#include "engine/scenes/triaxial.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace demcal::calibrate {

const std::vector<std::string>& metric_aliases() {
  static const std::vector<std::string> names = {"phi_peak", "phi_cv", "phi_diff", "repose"};
  return names;
}

bool is_alias(const std::string& name) {
  const auto& a = metric_aliases();
  return std::find(a.begin(), a.end(), name) != a.end();
}

namespace {
// The unit a stored metric's name ends with (the scenes' naming: angles *_deg,
// stresses *_pa, times *_s); "" for a pure number (porosity, a ratio, a count).
bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() > tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

std::string unit_of(const std::string& name) {
  // A rate: drift_per_simulated_s is 1/s, wall_s_per_simulated_s a pure ratio.
  for (const std::string per : {"_per_simulated_s", "_per_s"})
    if (ends_with(name, per)) return ends_with(name.substr(0, name.size() - per.size()), "_s") ? "" : "1/s";
  static const std::pair<const char*, const char*> suffixes[] = {
      {"_deg", "deg"}, {"_pa", "Pa"}, {"_kpa", "kPa"}, {"_s", "s"}, {"_j", "J"}, {"_m", "m"}};
  for (const auto& [tail, unit] : suffixes)
    if (ends_with(name, tail)) return unit;
  return "";
}
}  // namespace

MetricSpec metric_spec(const std::string& name) {
  if (name == "phi_peak") return {name, "phi_peak (deg)", "phi_peak_deg", "", "deg"};
  if (name == "phi_cv") return {name, "phi_cv (deg)", "phi_cv_deg", "", "deg"};
  if (name == "phi_diff") return {name, "phi_peak - phi_cv (deg)", "phi_peak_deg", "phi_cv_deg", "deg"};
  if (name == "repose") return {name, "angle of repose (deg)", "repose_deg", "", "deg"};
  // A stored name an alias reads (phi_peak_deg) is labelled as the alias is.
  for (const auto& a : metric_aliases()) {
    const MetricSpec s = metric_spec(a);
    if (s.minus.empty() && s.plus == name) return {name, s.label, s.plus, "", s.unit};
  }
  const std::string unit = unit_of(name);
  return {name, unit.empty() ? name : name + " (" + unit + ")", name, "", unit};
}

std::pair<std::string, std::string> stored_reading(const std::string& name) {
  const MetricSpec s = metric_spec(name);
  if (s.plus == "phi_diff_deg" && s.minus.empty()) return {"phi_peak_deg", "phi_cv_deg"};
  return {s.plus, s.minus};
}

std::optional<double> metric_value(const MetricSpec& spec, const std::vector<std::pair<std::string, double>>& metrics) {
  auto find = [&](const std::string& n) -> std::optional<double> {
    for (const auto& [k, v] : metrics)
      if (k == n && std::isfinite(v)) return v;
    return std::nullopt;
  };
  const auto a = find(spec.plus);
  if (!a) return std::nullopt;
  if (spec.minus.empty()) return a;
  const auto b = find(spec.minus);
  if (!b) return std::nullopt;
  return *a - *b;
}

bool peak_on_a_spike(const std::vector<std::pair<std::string, double>>& metrics) {
  double peak = NAN, smoothed = NAN, rows_to_end = NAN;
  for (const auto& [name, value] : metrics) {
    if (name == "phi_peak_deg") peak = value;
    if (name == "phi_peak_smoothed_deg") smoothed = value;
    if (name == "phi_peak_rows_to_end") rows_to_end = value;
  }
  return engine::TriaxialResult::peak_on_a_spike(peak, smoothed, rows_to_end);
}

std::string spike_rule() {
  char text[160];
  std::snprintf(text, sizeof text,
                "more than %g deg above the peak of its %d-row running mean, outside the series' last %d rows",
                engine::TriaxialResult::kPeakTransientDeg, engine::TriaxialResult::kPeakSmoothingRows,
                engine::TriaxialResult::kPeakSmoothingRows / 2);
  return text;
}

std::string running_mean_vs_spike() {
  static_assert(engine::TriaxialResult::kPeakSmoothingRows == 5, "the text below counts fifths of the 5-row window");
  return "which a spike of one or two rows moves by at most two fifths of its height";
}

}  // namespace demcal::calibrate
