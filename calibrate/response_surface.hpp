#pragma once
// A response surface: one calibration metric over the (theta, eta) grid of a job,
// replicas averaged with their spread kept, and the grid points that have no value
// (failed, unfinished or missing tasks) kept as holes.
#include "metric.hpp"

#include "db/store.hpp"
#include "jobs/query.hpp"

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace demcal::calibrate {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

struct GridPoint {
  double theta = 0, eta = 0;   // theta in degrees
  std::vector<double> values;  // one per replica with a value
  std::vector<std::int64_t> tasks;  // the task each value came from (empty for synthetic surfaces)
  double mean = kNaN, sd = kNaN, se = kNaN;  // sd, se: NaN with fewer than 2 replicas
  int failed = 0, unfinished = 0, missing = 0;  // tasks without a value, by reason
  int invalid = 0;  // of the failed, those that ran but were no test (a triaxial's servo lost): a rerun repeats them
  // A node of the job's (theta, eta) grid with no task in this database at all (a
  // shard not merged yet, a part not run): a hole as much as a failed task.
  bool absent = false;
  int spiked = 0;              // values whose phi_peak rests on a spike (metrics built on phi_peak_deg)
  bool refine = false;         // added by `demcal fit --refine`, not part of the job's grid
  int n() const { return static_cast<int>(values.size()); }
  bool hole() const { return values.empty(); }
  // A point with a value whose other replicas have none: its mean rests on fewer.
  bool partial() const { return !hole() && failed + unfinished + missing > 0; }
  // Why tasks of the point have no value: "1 failed, 2 not finished", "not in this database".
  std::string without_value() const;
};

struct Box {
  double theta_lo = 0, theta_hi = 0, eta_lo = 0, eta_hi = 0;
};

struct ResponseSurface {
  std::string job, metric, label;
  std::vector<GridPoint> points;     // grid points first (job order), then refinement points
  std::vector<double> thetas, etas;  // the job grid's distinct axis values, ascending
  double pooled_sd = kNaN;           // replica standard deviation pooled over points with n >= 2
  int warned = 0;                    // finished tasks used that carry warnings (not quasi-static, ...)
  std::string first_warning;         // the first of them (db::task_message's warning)
  // Of the results used, those whose phi_cv window the run judged not at critical
  // state (still dilating, or phi_mob drifting): counted for metrics built on phi_cv.
  int not_critical = 0;
  // Of the results used, those whose phi_peak rests on a spike (peak_on_a_spike):
  // counted for metrics built on phi_peak_deg.
  int on_spike = 0;

  Box box() const;                   // the job grid's bounds
  Box data_box() const;              // the bounds of the points that have data
  // Distinct theta (eta) values of the points that have data, ascending.
  std::vector<double> data_thetas() const;
  std::vector<double> data_etas() const;
  int holes() const;
  int with_data() const;
  int partials() const;  // grid points with a value that lack some replicas' (GridPoint::partial)
  // The partial points, "theta 40, eta 0: 1 of 2 (1 failed)", up to `max`, then how many more.
  std::string partial_list(std::size_t max = 4) const;
  // Standard error of a mean of a typical point: pooled_sd / sqrt(mean replica count);
  // 0 when no point has replicas (then the spread is unknown, and only the
  // surrogate's leave-one-out error measures the noise).
  double replica_se() const;
  // Fills mean, sd, se and pooled_sd from the values.
  void summarise();
  // What the results used stand on, one sentence each (empty when nothing to say), for
  // a fit's and a map's output alike: how many come from a window the run judged not
  // at critical state, and how many carry any warning, with the first of them.
  // `hint` tells where to see which (jobs::query_hint).
  std::string not_critical_note(const std::string& hint) const;
  std::string warned_note(const std::string& hint) const;
};

struct GatherOptions {
  std::vector<jobs::Where> where;  // filters on task parameters, as in `demcal query`
  bool include_refine = true;      // points from the job's refinement rounds
  std::string field = "--metric";  // the option named in errors about the metric
};

// Reads the metric for every task of `job` (and its refinement sub-jobs) and groups
// by (theta_deg, eta). Throws JobError naming the option for bad input: no such job,
// unknown metric, no data, tasks varying another parameter besides theta and eta.
ResponseSurface gather(db::Store& store, const std::string& job, const std::string& metric,
                       const GatherOptions& options = {});

// Refinement rounds of job J are stored as jobs named J.refine<k>.
std::string refine_job_name(const std::string& job, int round);
bool is_refine_job(const std::string& name);
// J's refinement sub-jobs, by round.
std::vector<std::string> refine_jobs_of(db::Store& store, const std::string& job);
// The round a sub-job name carries (J.refine3 -> 3); 0 for any other name.
int refine_round(const std::string& name);
// Jobs that are not refinement sub-jobs, by name.
std::vector<std::string> base_jobs(db::Store& store);

}  // namespace demcal::calibrate
