#include "calibration.hpp"
#include "excerpt.hpp"

#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/material_params.hpp"
#include "jobs/query.hpp"
#include "jobs/runner.hpp"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>

namespace demcal::calibrate {
namespace {

using jobs::JobError;

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + v[i];
  return s;
}

bool job_has_metric(db::Store& store, const std::string& job, const MetricSpec& spec) {
  for (const auto& t : store.tasks(job))
    for (const auto& m : store.metrics(t.id))
      if (m.first == spec.plus) return true;
  return false;
}

double round_to(double v, double q) { return std::round(v / q) * q; }

std::string num(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

std::string values_list(const std::vector<double>& v) {
  std::string s;
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + num(v[i]);
  return s;
}

// Two values on an axis cannot show a surface's curvature, and a leave-one-out error
// measured on them cannot see it either: the fit would be confidently wrong.
void require_levels(const ResponseSurface& rs, const std::string& job) {
  const auto t = rs.data_thetas(), e = rs.data_etas();
  if (t.size() >= 3 && e.size() >= 3) return;
  throw JobError("--job", "job \"" + job + "\" has " + rs.metric + " at " + std::to_string(t.size()) + " theta value(s) (" +
                              values_list(t) + ") and " + std::to_string(e.size()) + " eta value(s) (" + values_list(e) +
                              "); a fit over (theta, eta) needs at least 3 of each: with 2 the surface is a plane along that "
                              "axis and its error estimate cannot see the curvature it misses");
}

// Targets that read the same stored metric (phi_peak and phi_peak_deg), or a
// difference beside both its terms (phi_diff with phi_peak and phi_cv, under either
// name): the misfit would count the same residual twice (a region too small).
void refuse_redundant(const std::vector<Target>& targets) {
  std::map<std::pair<std::string, std::string>, std::string> reads;  // (plus, minus) -> the target's name
  for (const auto& t : targets) {
    const auto [plus, minus] = stored_reading(t.metric);
    const auto [it, fresh] = reads.emplace(std::make_pair(plus, minus), t.metric);
    if (fresh) continue;
    if (it->second == t.metric) throw JobError("--target", "metric \"" + t.metric + "\" given twice");
    throw JobError("--target", "\"" + it->second + "\" and \"" + t.metric + "\" are the same stored metric (" + plus +
                                   (minus.empty() ? "" : " - " + minus) +
                                   "): the misfit would count its residual twice; give it once");
  }
  // Two readings of one angle (the walls' raw peak and its running mean, or the walls'
  // and the interior's stress): their errors are one sample's, not independent ones.
  static const std::vector<std::vector<std::string>> same_angle = {
      {"phi_peak_deg", "phi_peak_smoothed_deg", "phi_peak_interior_deg"}, {"phi_cv_deg", "phi_cv_interior_deg"}};
  for (const auto& group : same_angle) {
    std::vector<std::string> given;
    for (const auto& [read, name] : reads)
      if (read.second.empty() && std::find(group.begin(), group.end(), read.first) != group.end()) given.push_back(name);
    if (given.size() > 1)
      throw JobError("--target", "\"" + given[0] + "\" and \"" + given[1] + "\" read the same angle of the same runs " +
                                     "(two ways of measuring one peak or one critical state): the misfit would count " +
                                     "one sample's error twice; target one of them");
  }
  for (const auto& [diff, name] : reads) {
    if (diff.second.empty()) continue;
    const auto plus = reads.find({diff.first, ""}), minus = reads.find({diff.second, ""});
    if (plus != reads.end() && minus != reads.end())
      throw JobError("--target", name + " is " + plus->second + " - " + minus->second +
                                     ": with targets for both it adds nothing and would count their residuals twice; "
                                     "give two of the three");
  }
}

// "at theta 40" / "at eta >= 0.3" ...: the part of the job's box without data.
std::string box_cut(const Box& job, const Box& data) {
  std::vector<std::string> parts;
  if (data.theta_lo > job.theta_lo) parts.push_back("below theta " + num(data.theta_lo));
  if (data.theta_hi < job.theta_hi) parts.push_back("above theta " + num(data.theta_hi));
  if (data.eta_lo > job.eta_lo) parts.push_back("below eta " + num(data.eta_lo));
  if (data.eta_hi < job.eta_hi) parts.push_back("above eta " + num(data.eta_hi));
  std::string s;
  for (std::size_t i = 0; i < parts.size(); ++i) s += (i ? ", " : "") + parts[i];
  return s;
}

// The job-grid points without a value that are corners of a grid cell the fit's
// region (or its best point) lies in: "theta 25, eta 0.3; ..."; "" when none.
std::string gaps_under(const ResponseSurface& rs, const FitResult& fit) {
  if (rs.thetas.size() < 2 || rs.etas.size() < 2) return "";
  // The index of the cell's lower corner. A point on the searched box's upper edge
  // lies in the cell below it: the cell above is outside the box (a failed row the fit
  // was cut short of).
  auto cell = [](const std::vector<double>& axis, double x, double hi) {
    const auto it = std::upper_bound(axis.begin(), axis.end(), x);
    int c = std::clamp(static_cast<int>(it - axis.begin()) - 1, 0, static_cast<int>(axis.size()) - 2);
    if (c > 0 && axis[static_cast<std::size_t>(c)] >= hi) --c;
    return c;
  };
  const std::size_t nt = rs.thetas.size();
  std::vector<char> used((nt - 1) * (rs.etas.size() - 1), 0);
  auto mark = [&](double th, double et) {
    used[cell(rs.etas, et, fit.box.eta_hi) * (nt - 1) + cell(rs.thetas, th, fit.box.theta_hi)] = 1;
  };
  mark(fit.theta, fit.eta);
  const Region& R = fit.region;
  for (int j = 0; j < R.n; ++j)
    for (int i = 0; i < R.n; ++i)
      if (R.mask[static_cast<std::size_t>(j)][static_cast<std::size_t>(i)] == '1')
        mark(fit.box.theta_lo + (fit.box.theta_hi - fit.box.theta_lo) * i / (R.n - 1),
             fit.box.eta_lo + (fit.box.eta_hi - fit.box.eta_lo) * j / (R.n - 1));
  std::string s;
  for (const auto& p : rs.points) {
    if (!p.hole() || p.refine) continue;
    const auto ti = std::lower_bound(rs.thetas.begin(), rs.thetas.end(), p.theta) - rs.thetas.begin();
    const auto ei = std::lower_bound(rs.etas.begin(), rs.etas.end(), p.eta) - rs.etas.begin();
    bool under = false;  // any of the (up to) four cells the point is a corner of
    for (long a = ti - 1; a <= ti; ++a)
      for (long b = ei - 1; b <= ei; ++b)
        if (a >= 0 && b >= 0 && a < static_cast<long>(nt) - 1 && b < static_cast<long>(rs.etas.size()) - 1)
          under = under || used[static_cast<std::size_t>(b) * (nt - 1) + static_cast<std::size_t>(a)];
    if (under) s += (s.empty() ? "" : "; ") + ("theta " + num(p.theta) + ", eta " + num(p.eta));
  }
  return s;
}

}  // namespace

std::string job_for_metric(db::Store& store, const std::string& metric, const std::vector<std::string>& jobs_in,
                           const std::vector<jobs::Where>& where, const std::string& metric_flag) {
  (void)where;
  for (const auto& j : jobs_in) {
    // Else "stored by more than one of the jobs named (grid, grid)".
    if (std::count(jobs_in.begin(), jobs_in.end(), j) > 1) throw JobError("--job", "\"" + j + "\" given twice");
    if (!store.find_job(j)) {
      const auto all = base_jobs(store);
      throw JobError("--job", "no job named \"" + j + "\"" + (all.empty() ? " (the database holds no jobs)" : " (jobs: " + join(all) + ")"));
    }
  }
  const std::vector<std::string> pool = jobs_in.empty() ? base_jobs(store) : jobs_in;
  if (pool.empty()) throw JobError("--job", "no data: the database holds no jobs");
  if (pool.size() == 1) return pool.front();
  const MetricSpec spec = metric_spec(metric);
  std::vector<std::string> have;
  for (const auto& j : pool)
    if (job_has_metric(store, j, spec)) have.push_back(j);
  if (have.empty()) {
    if (!is_alias(metric))
      throw JobError(metric_flag, "unknown metric \"" + metric + "\" (expected " + join(metric_aliases()) +
                                     ", or a metric some job stores); jobs searched: " + join(pool));
    throw JobError(metric_flag, "no data: no job stores " + spec.plus + " for " + metric + " (jobs searched: " + join(pool) + ")");
  }
  if (have.size() > 1) {
    if (jobs_in.empty())
      throw JobError("--job", metric + " is stored by several jobs (" + join(have) + "); name the one to use with --job");
    throw JobError("--job", metric + " is stored by more than one of the jobs named (" + join(have) +
                                "): a fit takes each target from one job; name only one of these");
  }
  return have.front();
}

std::string material_mismatch(db::Store& store, const std::vector<std::string>& job_names) {
  if (job_names.size() < 2) return "";
  std::map<std::string, std::map<std::string, std::set<std::string>>> values;  // key -> job -> values
  for (const auto& job : job_names)
    for (const auto& t : store.tasks(job)) {
      nlohmann::json p;
      try {
        p = nlohmann::json::parse(t.params_json);
      } catch (const std::exception&) {
        continue;
      }
      for (const auto& spec : jobs::material_params()) {
        if (spec.name == "theta_deg" || spec.name == "eta") continue;
        // A key the task leaves out takes the default a job file's would: compared as that.
        const nlohmann::json& v = p.contains(spec.name) ? p[spec.name] : spec.fallback;
        values[spec.name][job].insert(v.is_null() ? std::string("(default)") : v.dump());
      }
    }
  std::vector<std::string> differ;
  for (const auto& [key, per_job] : values) {
    std::set<std::set<std::string>> distinct;
    for (const auto& [job, v] : per_job) distinct.insert(v);
    if (distinct.size() < 2) continue;
    std::string d = key + ":";
    for (const auto& [job, v] : per_job) {
      std::string shown;
      for (const auto& x : v) shown += (shown.empty() ? "" : "|") + (x.size() > 40 ? x.substr(0, 37) + "..." : x);
      d += " " + shown + " (" + job + ")";
    }
    differ.push_back(d);
  }
  if (differ.empty()) return "";
  std::string all;
  for (const auto& d : differ) all += (all.empty() ? "" : "; ") + d;
  return "the jobs fitted together do not share one material (" + all +
         "): the fit takes their metrics as one material's; rerun one job with the other's material section";
}

namespace {

// One model per target, on the job storing its metric; returns the box where every
// surrogate has data (failed edge rows cut it), with a warning for each cut.
Box build_models(db::Store& store, const FitRequest& req, Calibration& cal, std::vector<std::string>& warnings) {
  Box box;
  bool first = true;
  for (const auto& t : req.targets) {
    const std::string job = job_for_metric(store, t.metric, req.jobs, req.where);
    GatherOptions go;
    go.where = req.where;
    go.field = "--target";
    ResponseSurface rs = gather(store, job, t.metric, go);
    require_levels(rs, job);
    Model m;
    m.metric = t.metric;
    m.label = rs.label;
    m.job = job;
    try {
      m.surrogate = fit_surrogate(rs);
    } catch (const std::invalid_argument& e) {
      throw JobError("--job", "job \"" + job + "\", " + t.metric + ": " + e.what() + " (" + std::to_string(rs.with_data()) +
                                  " points with data, " + std::to_string(rs.holes()) + " holes)");
    }
    m.replica_se = rs.replica_se();
    // The surrogate is trusted where its points are: failed edge rows cut the box.
    const Box b = rs.data_box();
    if (const std::string cut = box_cut(rs.box(), b); !cut.empty())
      warnings.push_back("job " + job + " has no " + t.metric + " " + cut + ": the fit searches only where there is data");
    if (first) {
      box = b;
      first = false;
    } else {
      box.theta_lo = std::max(box.theta_lo, b.theta_lo);
      box.theta_hi = std::min(box.theta_hi, b.theta_hi);
      box.eta_lo = std::max(box.eta_lo, b.eta_lo);
      box.eta_hi = std::min(box.eta_hi, b.eta_hi);
    }
    cal.surfaces.push_back(std::move(rs));
    cal.models.push_back(std::move(m));
  }
  if (!(box.theta_hi > box.theta_lo) || !(box.eta_hi > box.eta_lo)) {
    std::set<std::string> js;
    for (const auto& m : cal.models) js.insert(m.job);
    throw JobError("--job", "the grids of jobs " + join(std::vector<std::string>(js.begin(), js.end())) +
                                " do not overlap in (theta, eta)");
  }
  return box;
}

// The replica correlation of every pair of targets on one job.
std::vector<PairCorrelation> replica_correlations(const Calibration& cal) {
  std::vector<PairCorrelation> correlations;
  for (std::size_t k = 0; k < cal.surfaces.size(); ++k)
    for (std::size_t l = k + 1; l < cal.surfaces.size(); ++l)
      if (cal.surfaces[k].job == cal.surfaces[l].job)
        correlations.push_back({k, l, replica_correlation(cal.surfaces[k], cal.surfaces[l])});
  return correlations;
}

// Jobs fitted together on different materials, and --job's that hold no target.
void warn_about_jobs(db::Store& store, const FitRequest& req, Calibration& cal) {
  std::set<std::string> used;
  for (const auto& m : cal.models) used.insert(m.job);
  if (const std::string w = material_mismatch(store, {used.begin(), used.end()}); !w.empty())
    cal.result.warnings.push_back(w);
  for (const auto& j : req.jobs)
    if (!used.count(j))
      cal.result.warnings.push_back("job " + j + " (--job) stores none of the targets' metrics: the fit does not use it");
}

// Holes under the 95% region, one warning per set of gaps: metrics of one job share
// their failed tasks.
void warn_about_gaps(Calibration& cal) {
  if (!cal.result.ok) return;
  std::vector<std::pair<std::string, std::string>> gaps;  // gaps, metrics
  for (std::size_t k = 0; k < cal.surfaces.size(); ++k) {
    const std::string g = gaps_under(cal.surfaces[k], cal.result);
    if (g.empty()) continue;
    auto it = std::find_if(gaps.begin(), gaps.end(), [&](const auto& e) { return e.first == g; });
    if (it == gaps.end())
      gaps.emplace_back(g, cal.models[k].metric);
    else
      it->second += " and " + cal.models[k].metric;
  }
  for (const auto& [g, metrics] : gaps)
    cal.result.warnings.push_back("the 95% region lies on grid cells where " + metrics +
                                  (metrics.find(" and ") == std::string::npos ? " has" : " have") +
                                  " no value at a corner (" + g +
                                  "): the surrogate bridges the gap there; finish unfinished tasks (demcal run), "
                                  "merge or run missing ones, and change the settings of failed or invalid ones "
                                  "(a rerun repeats them, unless a worker was killed)");
}

// What the surrogates stand on: points short of replicas, windows not at critical
// state, peaks on a spike, and results carrying warnings.
void warn_about_results(db::Store& store, Calibration& cal) {
  // A point that lost a replica averages the others: with replicas that differ
  // systematically (another packing) its mean moves by their spread, and nothing in
  // the numbers shows it. Once a job: its metrics share the tasks.
  std::set<std::string> told;  // job and list: a metric missing on one task has its own
  for (const auto& rs : cal.surfaces)
    if (rs.partials() > 0 && told.insert(rs.job + "\n" + rs.partial_list()).second)
      cal.result.warnings.push_back(std::to_string(rs.partials()) + " point(s) of job " + rs.job +
                                    " have a value from fewer replicas than they have tasks (" + rs.partial_list() +
                                    "): their means rest on the replicas that finished, and may be biased; demcal "
                                    "status shows why tasks failed, demcal run finishes unfinished ones");
  // Said once a job, from the surface with the most warned results.
  std::map<std::string, const ResponseSurface*> warned;
  for (const auto& rs : cal.surfaces)
    if (rs.warned > 0 && (!warned.count(rs.job) || rs.warned > warned[rs.job]->warned)) warned[rs.job] = &rs;
  // Results whose phi_cv window was not at critical state enter a critical-state fit as
  // if they were: say how many, per metric, apart from the general note.
  for (const auto& rs : cal.surfaces)
    if (const std::string note = rs.not_critical_note(jobs::query_hint(store.path(), rs.job)); !note.empty())
      cal.result.warnings.push_back(note);
  // A peak taken from a spike of one or two rows reads degrees above the curve's hump.
  for (const auto& rs : cal.surfaces)
    if (rs.on_spike > 0)
      cal.result.warnings.push_back(std::to_string(rs.on_spike) + " of the " + rs.metric + " results used from job " +
                                    rs.job + " take phi_peak from a spike of the walls' stress (" + spike_rule() + ") "
                                    "(" + jobs::query_hint(store.path(), rs.job) + " shows which): the surrogate takes the spike as "
                                    "peak strength; a target on phi_peak_smoothed_deg fits the peak of the running "
                                    "mean instead");
  for (const auto& [job, rs] : warned) cal.result.warnings.push_back(rs->warned_note(jobs::query_hint(store.path(), job)));
}

}  // namespace

Calibration calibrate(db::Store& store, const FitRequest& req) {
  if (req.targets.empty()) throw JobError("--target", "give at least one target, e.g. --target phi_peak=41.4");
  refuse_redundant(req.targets);
  Calibration cal;
  std::vector<std::string> data_cuts;
  const Box box = build_models(store, req, cal, data_cuts);
  cal.result = invert(cal.models, req.targets, box, req.options, replica_correlations(cal));
  for (const auto& c : data_cuts) cal.result.warnings.push_back(c);
  warn_about_jobs(store, req, cal);
  warn_about_gaps(cal);
  warn_about_results(store, cal);
  return cal;
}

FitRecord fit_record(const FitRequest& req, const Calibration& cal, int round, const nlohmann::json& extra) {
  nlohmann::json targets = nlohmann::json::array();
  for (const auto& t : req.targets)
    targets.push_back({{"metric", t.metric}, {"value", t.value},
                       {"sigma", std::isfinite(t.sigma) ? nlohmann::json(t.sigma) : nlohmann::json(nullptr)}});
  nlohmann::json r = cal.result.to_json();
  std::set<std::string> js;
  nlohmann::json surrogates = nlohmann::json::array();
  for (std::size_t k = 0; k < cal.models.size(); ++k) {
    js.insert(cal.models[k].job);
    const auto& s = cal.models[k].surrogate;
    surrogates.push_back({{"metric", cal.models[k].metric}, {"job", cal.models[k].job}, {"kind", kind_name(s.kind())},
                          {"smoothing", s.lambda()}, {"loo_rms", s.loo_rms()}, {"loo_max", s.loo_max()},
                          {"points", s.points()}, {"holes", cal.surfaces[k].holes()},
                          {"partial", cal.surfaces[k].partials()}});
  }
  r["jobs"] = std::vector<std::string>(js.begin(), js.end());
  r["surrogates"] = surrogates;
  r["round"] = round;
  nlohmann::json where = nlohmann::json::object();
  for (const auto& w : req.where) where[w.key] = w.value;
  r["where"] = where;
  for (const auto& [k, v] : extra.items()) r[k] = v;
  return {targets, cal.result.method + "; surrogate chosen by leave-one-out", r};
}

std::int64_t store_fit(db::Store& store, const FitRequest& req, const Calibration& cal, int round, const nlohmann::json& extra) {
  const FitRecord rec = fit_record(req, cal, round, extra);
  return store.add_fit(rec.targets.dump(), rec.method, rec.result.dump());
}

std::vector<RefinePoint> refine_points(const ResponseSurface& rs, double theta, double eta, int round) {
  const Box b = rs.box();
  auto spacing = [](const std::vector<double>& axis) {
    return axis.size() < 2 ? 0.0 : (axis.back() - axis.front()) / static_cast<double>(axis.size() - 1);
  };
  const double scale = std::pow(0.5, round);
  const double ht = spacing(rs.thetas) * scale, he = spacing(rs.etas) * scale;
  // Round so repeated rounds produce identical parameters (and task keys).
  const double tc = round_to(theta, 1e-3), ec = round_to(eta, 1e-5);
  const double tn = round_to(tc + (tc + ht <= b.theta_hi ? ht : -ht), 1e-3);
  const double en = round_to(ec + (ec + he <= b.eta_hi ? he : -he), 1e-5);
  return {{tc, ec}, {tn, ec}, {tc, en}, {tn, en}};
}

namespace {

std::set<std::string> fitted_jobs(const Calibration& cal) {
  std::set<std::string> js;
  for (const auto& m : cal.models) js.insert(m.job);
  return js;
}

int unfinished_tasks(db::Store& store, const std::string& job) {
  int n = 0;
  const db::StatusCounts all = store.counts(job);
  const auto it = all.find(job);
  if (it == all.end()) return 0;
  for (const auto& [status, count] : it->second)
    if (status != "done" && status != "failed") n += count;
  return n;
}

// The highest round stored for any of the jobs (0: none).
int last_round(db::Store& store, const std::set<std::string>& jobs_fitted) {
  int last = 0;
  for (const auto& job : jobs_fitted)
    for (const auto& sub : refine_jobs_of(store, job)) last = std::max(last, refine_round(sub));
  return last;
}

// Refits after a round's runs: the new candidate into `rec`, and how far it moved
// from the one before, in fractions of the grid's range.
void refit(db::Store& store, const FitRequest& req, Calibration& cal, RefineRound& rec) {
  const double theta0 = cal.result.theta, eta0 = cal.result.eta;
  cal = calibrate(store, req);
  rec.ok = cal.result.ok;
  rec.theta = cal.result.theta;
  rec.eta = cal.result.eta;
  const Box& b = cal.result.box;
  rec.move = std::max(std::abs(rec.theta - theta0) / (b.theta_hi - b.theta_lo),
                      std::abs(rec.eta - eta0) / (b.eta_hi - b.eta_lo));
}

// Whether a stored round was run for other --where values than this fit reads (its
// spec's grid holds only the values the fit of that round was pinned to).
bool pinned_elsewhere(const nlohmann::json& spec, const std::vector<jobs::Where>& where) {
  if (!spec.contains("grid") || !spec["grid"].is_object()) return false;
  for (const auto& w : where) {
    if (!spec["grid"].contains(w.key) || !spec["grid"][w.key].is_array()) continue;
    const auto& values = spec["grid"][w.key];
    if (std::none_of(values.begin(), values.end(), [&](const nlohmann::json& v) { return jobs::value_matches(v, w.value); }))
      return true;
  }
  return false;
}

// Round r's points, as a stored sub-job's grid holds them (theta x eta).
std::vector<RefinePoint> points_of(const nlohmann::json& spec) {
  std::vector<RefinePoint> pts;
  const auto& g = spec.at("grid");
  for (const auto& th : g.at("theta_deg"))
    for (const auto& et : g.at("eta")) pts.push_back({th.get<double>(), et.get<double>()});
  return pts;
}

// The last stored round R of the fitted jobs, finished: a job whose R sub-job has
// unfinished runs (an interrupt, a lost worker) gets them run; a job without an R
// sub-job while another has one (the round was cut short before it came to that job)
// gets R's points. A round run for other --where values is left alone, and one that
// can no longer be run (its spec, its output folder) is reported and passed over, so
// that it never blocks new rounds. Returns that round's record, or none if nothing ran.
std::optional<RefineRound> resume_last_round(db::Store& store, const FitRequest& req, Calibration& cal,
                                             const RefineOptions& opt, std::ostream& log) {
  if (!opt.resume_round) return std::nullopt;
  const std::set<std::string> jobs_fitted = fitted_jobs(cal);
  const int last = last_round(store, jobs_fitted);
  if (last == 0) return std::nullopt;
  std::optional<std::vector<RefinePoint>> points;
  for (const auto& job : jobs_fitted)
    if (const auto text = store.job_spec(refine_job_name(job, last)); text && !points) try {
        points = points_of(nlohmann::json::parse(*text));
      } catch (const nlohmann::json::exception&) {
      }
  RefineRound rec;
  rec.resumed = true;
  rec.round = last;
  nlohmann::json resumed = nlohmann::json::array();
  for (const auto& job : jobs_fitted) {
    const std::string sub = refine_job_name(job, last);
    const auto text = store.job_spec(sub);
    if (!text) {
      if (!points) continue;
      log << "refine: round " << last << " stopped before job " << job << "; running its " << points->size()
          << " point(s) there\n";
      opt.run_points(store, job, last, *points);
      resumed.push_back(sub);
      continue;
    }
    const int open = unfinished_tasks(store, sub);
    if (open == 0) continue;
    try {
      if (pinned_elsewhere(nlohmann::json::parse(*text), req.where)) {
        log << "refine: round " << last << " of job " << job << " has " << open
            << " unfinished run(s) for other --where values than this fit's; left as it is\n";
        continue;
      }
      log << "refine: resuming round " << last << " of job " << job << " (" << open << " run(s) unfinished)\n";
      opt.resume_round(store, sub);
      resumed.push_back(sub);
    } catch (const JobError& e) {
      log << "refine: warning: round " << last << " of job " << job << " cannot be resumed (" << e.what()
          << "); going on with new rounds\n";
    } catch (const nlohmann::json::exception& e) {
      log << "refine: warning: round " << last << " of job " << job << " has a spec this build cannot read (" << e.what()
          << "); going on with new rounds\n";
    }
  }
  if (resumed.empty()) return std::nullopt;
  refit(store, req, cal, rec);
  if (!rec.ok) rec.move = kNaN;
  rec.fit_id = store_fit(store, req, cal, rec.round, {{"refine", {{"resumed", resumed}}}});
  log << "refine round " << rec.round << " (resumed): candidate theta = " << rec.theta << ", eta = " << rec.eta
      << " (fit " << rec.fit_id << ")\n";
  return rec;
}

}  // namespace

std::vector<RefineRound> refine(db::Store& store, const FitRequest& req, Calibration& cal, const RefineOptions& opt) {
  std::vector<RefineRound> rounds;
  std::ostream& log = opt.log ? *opt.log : std::cerr;
  if (cal.result.ok)
    if (auto r = resume_last_round(store, req, cal, opt, log)) rounds.push_back(*r);
  // Numbered on from the last stored round of any fitted job: a job is its latest
  // spec, so reusing a round's name would drop that round's runs from the surfaces.
  const int last = last_round(store, fitted_jobs(cal));
  for (int k = 1; k <= opt.rounds; ++k) {
    const int r = last + k;
    if (!cal.result.ok) {
      log << "refine: stopping before round " << r << ": the current fit has no answer\n";
      break;
    }
    const double th0 = cal.result.theta, et0 = cal.result.eta;
    RefineRound rec;
    rec.round = r;
    // The spacing halves with each round of this invocation, from the grid's own:
    // the candidate of an earlier invocation (other targets, a grown grid) may be far.
    rec.points = refine_points(cal.surfaces.front(), th0, et0, k);
    for (const auto& job : fitted_jobs(cal)) {
      log << "refine round " << r << ": running " << rec.points.size() << " point(s) around theta = " << th0
          << ", eta = " << et0 << " for job " << job << "\n";
      opt.run_points(store, job, r, rec.points);
    }
    refit(store, req, cal, rec);
    nlohmann::json pts = nlohmann::json::array();
    for (const auto& p : rec.points) pts.push_back({p.theta, p.eta});
    rec.fit_id = store_fit(store, req, cal, r, {{"refine", {{"points", pts}, {"move", rec.move}, {"tolerance", opt.tolerance}}}});
    rounds.push_back(rec);
    log << "refine round " << r << ": candidate theta = " << rec.theta << ", eta = " << rec.eta << ", moved " << rec.move
        << " of the range (fit " << rec.fit_id << ")\n";
    if (rec.ok && rec.move < opt.tolerance) break;
  }
  return rounds;
}

namespace {

// A round's sub-job through the jobs runner: an interrupt ends the refinement, a
// failed run leaves a hole.
void run_round(db::Store& store, const jobs::Job& sub, const std::string& out_dir, int workers, std::ostream* log) {
  jobs::RunOptions ro;
  ro.workers = workers;
  ro.out_dir = out_dir;
  ro.log = log ? log : &std::cerr;
  const jobs::RunSummary s = jobs::run_job(store, sub, ro);
  if (s.interrupted)
    throw std::runtime_error(
        "refinement interrupted; finished runs are kept, and `demcal fit` with --refine again finishes the round first");
  if (s.superseded)
    throw std::runtime_error("refinement " + sub.name +
                             ": another `demcal fit --refine` recorded this round with other points while it ran; "
                             "finished runs of both are kept, and --refine again goes on from the last round");
  // Not a round with holes: the runs did not happen, and a round stored on them
  // would read as converged (it moved nothing) and end the refinement.
  jobs::throw_if_stopped_short(s, "refinement " + sub.name);
  if (s.unfinished > 0)
    throw std::runtime_error("refinement " + sub.name + ": " + std::to_string(s.unfinished) + " of " +
                             std::to_string(s.total) + " run(s) unfinished (held by another runner?); --refine again "
                             "finishes the round first");
  if (s.failed > 0) *ro.log << "refine: " << s.failed << " of " << s.total << " run(s) failed; they are holes\n";
}

}  // namespace

PointRunner dem_point_runner(const std::string& out_dir, int workers, std::ostream* log,
                             const std::vector<jobs::Where>& where) {
  return [out_dir, workers, log, where](db::Store& store, const std::string& job, int round,
                                        const std::vector<RefinePoint>& points) {
    const auto text = store.job_spec(job);
    if (!text) throw JobError("--job", "no job named \"" + job + "\"");
    nlohmann::json spec = nlohmann::json::parse(*text);
    std::set<double> th, et;
    for (const auto& p : points) th.insert(p.theta), et.insert(p.eta);
    spec["name"] = refine_job_name(job, round);
    if (!spec.contains("grid") || !spec["grid"].is_object()) spec["grid"] = nlohmann::json::object();
    spec["grid"]["theta_deg"] = std::vector<double>(th.begin(), th.end());
    spec["grid"]["eta"] = std::vector<double>(et.begin(), et.end());
    // A grid axis the fit was pinned to (--where packing=dense) runs at that value
    // only: the other values would cost runs the fit never reads.
    for (const auto& w : where) {
      if (!spec["grid"].contains(w.key)) continue;
      nlohmann::json pinned;
      for (const auto& v : spec["grid"][w.key])
        if (jobs::value_matches(v, w.value)) pinned = v;
      if (!pinned.is_null()) spec["grid"][w.key] = nlohmann::json::array({pinned});
    }
    if (spec.contains("material") && spec["material"].is_object()) {
      spec["material"].erase("theta_deg");
      spec["material"].erase("eta");
    }
    run_round(store, jobs::parse_job(spec.dump(), "refinement of job " + job), out_dir, workers, log);
  };
}

RoundResumer dem_round_resumer(const std::string& out_dir, int workers, std::ostream* log) {
  return [out_dir, workers, log](db::Store& store, const std::string& sub_job) {
    const auto text = store.job_spec(sub_job);
    if (!text) throw JobError("--job", "no job named \"" + sub_job + "\"");
    run_round(store, jobs::parse_job(*text, "refinement " + sub_job), out_dir, workers, log);
  };
}

}  // namespace demcal::calibrate
