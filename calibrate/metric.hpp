#pragma once
// Calibration metrics by name: the short names the CLI takes (phi_peak, phi_cv,
// phi_diff, repose) and any metric a scene stores under its own name.
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace demcal::calibrate {

struct MetricSpec {
  std::string name;   // as asked: "phi_peak" or a stored name
  std::string label;  // for plots and tables, e.g. "phi_peak (deg)"
  std::string plus;   // stored metric
  std::string minus;  // stored metric subtracted from `plus` ("" for none)
  std::string unit;   // "deg", "Pa", "s", ... from the stored name's suffix; "" for a pure number
};

// phi_peak, phi_cv, phi_diff, repose.
const std::vector<std::string>& metric_aliases();
// The alias, or a stored metric name used as it is.
MetricSpec metric_spec(const std::string& name);
// What a name reads, as (plus, minus) of stored metrics, the same for every name of
// one quantity: phi_peak and phi_peak_deg; phi_diff and the triaxial scene's stored
// phi_diff_deg (phi_peak_deg - phi_cv_deg).
std::pair<std::string, std::string> stored_reading(const std::string& name);
bool is_alias(const std::string& name);
// The value for one task, or nothing when the task lacks a stored metric it needs
// or the value is not finite.
std::optional<double> metric_value(const MetricSpec& spec, const std::vector<std::pair<std::string, double>>& metrics);
// Whether a triaxial result's phi_peak_deg rests on a spike: more than the scene's
// TriaxialResult::kPeakTransientDeg above phi_peak_smoothed_deg, the peak of its
// running mean, outside the series' last two rows (phi_peak_rows_to_end; results
// stored before it are judged by the angles alone). Judged from the stored values, so
// results stored before the scene warned of it count too; false when either angle is
// missing (older results, other scenes).
bool peak_on_a_spike(const std::vector<std::pair<std::string, double>>& metrics);
// "more than 2 deg above the peak of its 5-row running mean, outside the series' last
// 2 rows", from the same constants.
std::string spike_rule();
// What the running mean's peak owes a spike, as a relative clause that follows
// "the running mean's peak": one text for the study, map and help.
std::string running_mean_vs_spike();

}  // namespace demcal::calibrate
