#include "calibration.hpp"

#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/runner.hpp"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <set>

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

}  // namespace

std::string job_for_metric(db::Store& store, const std::string& metric, const std::vector<std::string>& jobs_in,
                           const std::vector<jobs::Where>& where) {
  (void)where;
  for (const auto& j : jobs_in)
    if (!store.find_job(j)) {
      const auto all = base_jobs(store);
      throw JobError("--job", "no job named \"" + j + "\"" + (all.empty() ? " (the database holds no jobs)" : " (jobs: " + join(all) + ")"));
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
      throw JobError("--target", "unknown metric \"" + metric + "\" (expected " + join(metric_aliases()) +
                                     ", or a metric some job stores); jobs searched: " + join(pool));
    throw JobError("--target", "no data: no job stores " + spec.plus + " for " + metric + " (jobs searched: " + join(pool) + ")");
  }
  if (have.size() > 1)
    throw JobError("--job", metric + " is stored by several jobs (" + join(have) + "); name the one to use with --job");
  return have.front();
}

Calibration calibrate(db::Store& store, const FitRequest& req) {
  if (req.targets.empty()) throw JobError("--target", "give at least one target, e.g. --target phi_peak=41.4");
  std::set<std::string> seen;
  for (const auto& t : req.targets)
    if (!seen.insert(t.metric).second) throw JobError("--target", "metric \"" + t.metric + "\" given twice");
  Calibration cal;
  Box box;
  bool first = true;
  for (const auto& t : req.targets) {
    const std::string job = job_for_metric(store, t.metric, req.jobs, req.where);
    GatherOptions go;
    go.where = req.where;
    go.field = "--target";
    ResponseSurface rs = gather(store, job, t.metric, go);
    if (rs.thetas.size() < 2 || rs.etas.size() < 2)
      throw JobError("--job", "job \"" + job + "\" has " + std::to_string(rs.thetas.size()) + " theta value(s) and " +
                                  std::to_string(rs.etas.size()) + " eta value(s); a fit over (theta, eta) needs at least 2 of each");
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
    const Box b = rs.box();
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
  cal.result = invert(cal.models, req.targets, box, req.options);
  // The surrogates stand on these results: say when they carry warnings, once a job.
  std::map<std::string, const ResponseSurface*> warned;
  for (const auto& rs : cal.surfaces)
    if (rs.warned > 0 && (!warned.count(rs.job) || rs.warned > warned[rs.job]->warned)) warned[rs.job] = &rs;
  for (const auto& [job, rs] : warned) {
    std::string w = rs->first_warning;
    if (w.size() > 160) w = w.substr(0, 157) + "...";
    int used = 0;
    for (const auto& p : rs->points) used += static_cast<int>(p.values.size());
    cal.result.warnings.push_back(std::to_string(rs->warned) + " of the " + std::to_string(used) + " results used from job " +
                                  job + " carry warnings (demcal query --job " + job + "), e.g.: " + w);
  }
  return cal;
}

std::int64_t store_fit(db::Store& store, const FitRequest& req, const Calibration& cal, int round, const nlohmann::json& extra) {
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
                          {"points", s.points()}, {"holes", cal.surfaces[k].holes()}});
  }
  r["jobs"] = std::vector<std::string>(js.begin(), js.end());
  r["surrogates"] = surrogates;
  r["round"] = round;
  nlohmann::json where = nlohmann::json::object();
  for (const auto& w : req.where) where[w.key] = w.value;
  r["where"] = where;
  for (const auto& [k, v] : extra.items()) r[k] = v;
  return store.add_fit(targets.dump(), cal.result.method + "; surrogate chosen by leave-one-out", r.dump());
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

std::vector<RefineRound> refine(db::Store& store, const FitRequest& req, Calibration& cal, const RefineOptions& opt) {
  std::vector<RefineRound> rounds;
  std::ostream& log = opt.log ? *opt.log : std::cerr;
  for (int r = 1; r <= opt.rounds; ++r) {
    if (!cal.result.ok) {
      log << "refine: stopping before round " << r << ": the current fit has no answer\n";
      break;
    }
    const double th0 = cal.result.theta, et0 = cal.result.eta;
    RefineRound rec;
    rec.round = r;
    rec.points = refine_points(cal.surfaces.front(), th0, et0, r);
    std::set<std::string> js;
    for (const auto& m : cal.models) js.insert(m.job);
    for (const auto& job : js) {
      log << "refine round " << r << ": running " << rec.points.size() << " point(s) around theta = " << th0
          << ", eta = " << et0 << " for job " << job << "\n";
      opt.run_points(store, job, r, rec.points);
    }
    cal = calibrate(store, req);
    rec.ok = cal.result.ok;
    rec.theta = cal.result.theta;
    rec.eta = cal.result.eta;
    const Box& b = cal.result.box;
    rec.move = std::max(std::abs(rec.theta - th0) / (b.theta_hi - b.theta_lo), std::abs(rec.eta - et0) / (b.eta_hi - b.eta_lo));
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

PointRunner dem_point_runner(const std::string& out_dir, int workers, std::ostream* log) {
  return [out_dir, workers, log](db::Store& store, const std::string& job, int round, const std::vector<RefinePoint>& points) {
    const auto text = store.job_spec(job);
    if (!text) throw JobError("--job", "no job named \"" + job + "\"");
    nlohmann::json spec = nlohmann::json::parse(*text);
    std::set<double> th, et;
    for (const auto& p : points) th.insert(p.theta), et.insert(p.eta);
    spec["name"] = refine_job_name(job, round);
    if (!spec.contains("grid") || !spec["grid"].is_object()) spec["grid"] = nlohmann::json::object();
    spec["grid"]["theta_deg"] = std::vector<double>(th.begin(), th.end());
    spec["grid"]["eta"] = std::vector<double>(et.begin(), et.end());
    if (spec.contains("material") && spec["material"].is_object()) {
      spec["material"].erase("theta_deg");
      spec["material"].erase("eta");
    }
    const jobs::Job sub = jobs::parse_job(spec.dump(), "refinement of job " + job);
    jobs::RunOptions ro;
    ro.workers = workers;
    ro.out_dir = out_dir;
    ro.log = log ? log : &std::cerr;
    const jobs::RunSummary s = jobs::run_job(store, sub, ro);
    if (s.interrupted) throw std::runtime_error("refinement interrupted; finished runs are kept");
    if (s.failed > 0) *ro.log << "refine: " << s.failed << " of " << s.total << " run(s) failed; they are holes\n";
  };
}

}  // namespace demcal::calibrate
