#include "response_surface.hpp"
#include "excerpt.hpp"

#include "jobs/job_error.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>

namespace demcal::calibrate {
namespace {

using jobs::JobError;

std::string join(const std::vector<std::string>& v, std::size_t max = 12) {
  std::string s;
  for (std::size_t i = 0; i < v.size() && i < max; ++i) s += (i ? ", " : "") + v[i];
  if (v.size() > max) s += ", ...";
  return s;
}


bool number_of(const nlohmann::json& p, const char* key, double& out) {
  if (!p.is_object() || !p.contains(key) || !p[key].is_number()) return false;
  out = p[key].get<double>();
  return true;
}

}  // namespace

Box ResponseSurface::box() const {
  Box b;
  if (thetas.empty() || etas.empty()) return b;
  b.theta_lo = thetas.front();
  b.theta_hi = thetas.back();
  b.eta_lo = etas.front();
  b.eta_hi = etas.back();
  return b;
}

namespace {
// Distinct values of one coordinate over the points that have data, ascending.
std::vector<double> data_values(const std::vector<GridPoint>& points, double GridPoint::*axis) {
  std::set<double> v;
  for (const auto& p : points)
    if (!p.hole()) v.insert(p.*axis);
  return {v.begin(), v.end()};
}
}  // namespace

std::vector<double> ResponseSurface::data_thetas() const { return data_values(points, &GridPoint::theta); }
std::vector<double> ResponseSurface::data_etas() const { return data_values(points, &GridPoint::eta); }

Box ResponseSurface::data_box() const {
  const auto t = data_thetas(), e = data_etas();
  if (t.empty() || e.empty()) return Box{};
  return {t.front(), t.back(), e.front(), e.back()};
}

std::string ResponseSurface::not_critical_note(const std::string& hint) const {
  if (not_critical == 0) return "";
  return std::to_string(not_critical) + " of the " + metric + " results used from job " + job +
         " come from a window the run judged not at critical state (still dilating or phi_mob drifting; " + hint +
         " shows which): the surrogate takes them as critical-state values";
}

std::string ResponseSurface::warned_note(const std::string& hint) const {
  if (warned == 0) return "";
  int used = 0;
  for (const auto& p : points) used += p.n();
  return std::to_string(warned) + " of the " + std::to_string(used) + " results used from job " + job +
         " carry warnings (" + hint + "), e.g.: " + cut_at_word(calibrate::first_warning(first_warning), 240);
}

int ResponseSurface::holes() const {
  int n = 0;
  for (const auto& p : points) n += p.hole() && !p.refine;
  return n;
}

std::string GridPoint::without_value() const {
  if (absent) return "no task here: not in this database, or not selected";
  std::string s;
  const auto add = [&](int n, const char* what) {
    if (n > 0) s += (s.empty() ? "" : ", ") + std::to_string(n) + " " + what;
  };
  add(failed - invalid, "failed");
  add(invalid, "invalid (no test)");
  add(unfinished, "not finished");
  add(missing, "without the metric");
  return s;
}

int ResponseSurface::partials() const {
  int n = 0;
  for (const auto& p : points) n += p.partial();
  return n;
}

std::string ResponseSurface::partial_list(std::size_t max) const {
  std::string s;
  std::size_t shown = 0, total = 0;
  for (const auto& p : points) {
    if (!p.partial()) continue;
    if (shown++ < max) {
      char head[96];
      std::snprintf(head, sizeof head, "theta %g, eta %g: %d of %d", p.theta, p.eta, p.n(),
                    p.n() + p.failed + p.unfinished + p.missing);
      s += (s.empty() ? "" : "; ") + std::string(head) + " (" + p.without_value() + ")";
    }
    ++total;
  }
  if (total > max) s += "; and " + std::to_string(total - max) + " more";
  return s;
}

int ResponseSurface::with_data() const {
  int n = 0;
  for (const auto& p : points) n += !p.hole();
  return n;
}

double ResponseSurface::replica_se() const {
  if (!std::isfinite(pooled_sd)) return 0.0;
  double total = 0;
  int k = 0;
  for (const auto& p : points)
    if (!p.hole()) {
      total += p.n();
      ++k;
    }
  return k ? pooled_sd / std::sqrt(total / k) : 0.0;
}

void ResponseSurface::summarise() {
  double ss = 0;
  int dof = 0;
  for (auto& p : points) {
    p.mean = p.sd = p.se = kNaN;
    if (p.hole()) continue;
    double m = 0;
    for (double v : p.values) m += v;
    m /= p.n();
    p.mean = m;
    if (p.n() < 2) continue;
    double s2 = 0;
    for (double v : p.values) s2 += (v - m) * (v - m);
    ss += s2;
    dof += p.n() - 1;
    p.sd = std::sqrt(s2 / (p.n() - 1));
    p.se = p.sd / std::sqrt(static_cast<double>(p.n()));
  }
  pooled_sd = dof > 0 ? std::sqrt(ss / dof) : kNaN;
}

std::string refine_job_name(const std::string& job, int round) { return job + ".refine" + std::to_string(round); }

bool is_refine_job(const std::string& name) {
  const auto at = name.rfind(".refine");
  if (at == std::string::npos || at + 7 >= name.size()) return false;
  return std::all_of(name.begin() + static_cast<long>(at) + 7, name.end(), [](char c) { return c >= '0' && c <= '9'; });
}

int refine_round(const std::string& name) {
  if (!is_refine_job(name)) return 0;
  // The round number as refine_job_name writes it; a longer run of digits (a job
  // of some other origin) is no round of ours.
  const std::string digits = name.substr(name.rfind(".refine") + 7);
  if (digits.size() > 6 || digits[0] == '0') return 0;
  return std::stoi(digits);
}

std::vector<std::string> refine_jobs_of(db::Store& store, const std::string& job) {
  std::vector<std::pair<int, std::string>> found;
  const std::string prefix = job + ".refine";
  for (const auto& [name, counts] : store.counts("")) {
    (void)counts;
    if (name.rfind(prefix, 0) != 0 || !is_refine_job(name) || name.find('.', prefix.size()) != std::string::npos)
      continue;
    const int round = refine_round(name);
    if (round > 0) found.emplace_back(round, name);
  }
  std::sort(found.begin(), found.end());
  std::vector<std::string> out;
  for (auto& f : found) out.push_back(f.second);
  return out;
}

std::vector<std::string> base_jobs(db::Store& store) {
  std::vector<std::string> out;
  for (const auto& [name, counts] : store.counts("")) {
    (void)counts;
    if (!is_refine_job(name)) out.push_back(name);
  }
  return out;
}

namespace {

// A task's result, and whether it comes from a refinement round.
struct Row {
  jobs::ResultRow r;
  bool refine;
};

// The job's tasks (and its refinement rounds', if asked) that the filters select.
std::vector<Row> read_rows(db::Store& store, const std::string& job, const GatherOptions& opt) {
  if (!store.find_job(job)) {
    const auto all = base_jobs(store);
    throw JobError("--job", "no job named \"" + job + "\"" +
                                (all.empty() ? " (the database holds no jobs)" : " (jobs: " + join(all) + ")"));
  }
  for (const auto& w : opt.where)
    if (w.key == "theta_deg" || w.key == "eta")
      throw JobError("--where", w.key + " is an axis of the surface (theta_deg and eta are what a map draws and a fit "
                                "finds); --where pins the other parameters");
  std::vector<Row> rows;
  std::string why_none;  // the filter that matched nothing, and the values its key takes
  for (auto& r : jobs::select_rows(store, job, opt.where, &why_none)) rows.push_back({std::move(r), false});
  if (opt.include_refine)
    for (const auto& sub : refine_jobs_of(store, job))
      for (auto& r : jobs::select_rows(store, sub, opt.where)) rows.push_back({std::move(r), true});
  if (rows.empty())
    throw JobError(opt.where.empty() ? "--job" : "--where",
                   "no data: job \"" + job + "\" has no tasks" +
                       (opt.where.empty() ? "" : " matching the filters" + (why_none.empty() ? "" : ": " + why_none)));
  return rows;
}

// A stored metric nobody has is an unknown metric, not missing data. Nobody: no task
// of the job, filtered or not (the filters may select only tasks that lack it).
void require_known_metric(db::Store& store, const std::string& job, const std::string& metric,
                          const GatherOptions& opt, const std::vector<Row>& rows) {
  std::set<std::string> stored;
  for (const auto& row : rows)
    for (const auto& m : row.r.metrics) stored.insert(m.first);
  if (!opt.where.empty() && !stored.count(metric))
    for (const auto& r : jobs::select_rows(store, job, {}))
      for (const auto& m : r.metrics) stored.insert(m.first);
  if (!is_alias(metric) && !stored.count(metric)) {
    std::string known = join(metric_aliases());
    throw JobError(opt.field, "unknown metric \"" + metric + "\" (expected " + known +
                                  (stored.empty() ? std::string() : ", or one job \"" + job + "\" stores: " +
                                                                        join(std::vector<std::string>(stored.begin(), stored.end()))) +
                                  ")");
  }
}

// No task holding the metric is the first thing to say: asking to pin a parameter
// first would only lead to this message one command later. (Past this check some
// grid point has a value, so the surface is never empty.)
void require_some_value(const std::string& job, const MetricSpec& spec, const GatherOptions& opt,
                        const std::vector<Row>& rows) {
  if (std::any_of(rows.begin(), rows.end(), [&](const Row& row) {
        return row.r.task.status == "done" && metric_value(spec, row.r.metrics).has_value();
      }))
    return;
  int done = 0, failed = 0;
  for (const auto& row : rows) {
    done += row.r.task.status == "done";
    failed += row.r.task.status == "failed";
  }
  const int unfinished = static_cast<int>(rows.size()) - done - failed;
  // Finished tasks without the metric: the metric is not this job's (a repose angle
  // asked of a triaxial job). None finished: the job has nothing yet.
  throw JobError(done > 0 ? opt.field : "--job", "no data: none of job \"" + job + "\"'s " + std::to_string(rows.size()) +
                              (opt.where.empty() ? "" : " selected") + " tasks has a stored " + (spec.minus.empty() ? spec.plus : spec.plus + " and " + spec.minus) +
                              " (" + std::to_string(done) + " done, " + std::to_string(failed) + " failed, " +
                              std::to_string(unfinished) + " not finished; scene " + rows.front().r.task.scene + ")");
}

// A job without a (theta, eta) grid cannot be mapped or fitted whatever is pinned (said
// before asking to pin anything); and only replicas may be averaged: any other
// parameter that varies must be pinned.
void require_one_grid(const std::string& job, const std::vector<Row>& rows) {
  std::set<std::string> th, et;
  for (const auto& row : rows) {
    if (row.r.params.contains("theta_deg")) th.insert(row.r.params["theta_deg"].dump());
    if (row.r.params.contains("eta")) et.insert(row.r.params["eta"].dump());
  }
  if (th.size() < 2 || et.size() < 2)
    throw JobError("--job", "job \"" + job + "\" (scene " + rows.front().r.task.scene +
                                ") is not a (theta, eta) grid: it has " + std::to_string(th.size()) +
                                " theta_deg and " + std::to_string(et.size()) +
                                " eta value(s); maps need at least 2 of each, fits 3");
  std::map<std::string, std::set<std::string>> seen;
  for (const auto& row : rows)
    for (const auto& [k, v] : row.r.params.items())
      if (k != "seed" && k != "theta_deg" && k != "eta") seen[k].insert(v.dump());
  for (const auto& [k, vals] : seen)
    if (vals.size() > 1)
      throw JobError("--where", "job \"" + job + "\" varies " + k + " (" + join(std::vector<std::string>(vals.begin(), vals.end())) +
                                    ") besides theta_deg and eta; pick one with --where " + k + "=VALUE");
}

using NodeKey = std::pair<long long, long long>;  // (theta, eta) rounded to 1e-9
NodeKey node_key(double th, double et) { return std::make_pair(std::llround(th * 1e9), std::llround(et * 1e9)); }

// Each row into its grid point: its value, or why it has none (failed, unfinished,
// done without the metric), and the warnings it carries. The grid's axes (of the
// non-refinement rows) into `thetas` and `etas`; `index` maps a node to its point.
void add_rows(ResponseSurface& rs, const std::string& job, const std::vector<Row>& rows, const MetricSpec& spec,
              std::map<NodeKey, std::size_t>& index, std::set<double>& thetas, std::set<double>& etas) {
  const auto [plus, minus] = stored_reading(rs.metric);
  const bool uses_cv = plus.rfind("phi_cv", 0) == 0 || minus.rfind("phi_cv", 0) == 0;
  const bool uses_peak = plus == "phi_peak_deg" || minus == "phi_peak_deg";
  for (const auto& row : rows) {
    double th = 0, et = 0;
    if (!number_of(row.r.params, "theta_deg", th) || !number_of(row.r.params, "eta", et))
      throw JobError("--job", "job \"" + job + "\" has tasks without theta_deg and eta parameters (scene " +
                                  row.r.task.scene + "); calibration needs a grid over both");
    auto it = index.find(node_key(th, et));
    if (it == index.end()) {
      it = index.emplace(node_key(th, et), rs.points.size()).first;
      GridPoint p;
      p.theta = th;
      p.eta = et;
      p.refine = row.refine;
      rs.points.push_back(p);
    }
    GridPoint& p = rs.points[it->second];
    if (!row.refine) {
      p.refine = false;  // a refinement point that coincides with the grid is a grid point
      thetas.insert(th);
      etas.insert(et);
    }
    const auto& st = row.r.task.status;
    if (st == "done") {
      if (auto v = metric_value(spec, row.r.metrics)) {
        p.values.push_back(*v);
        p.tasks.push_back(row.r.task.id);
        const std::string w = db::task_message(row.r.task).warning;
        if (!w.empty() && rs.warned++ == 0) rs.first_warning = w;
        if (uses_cv && says_not_at_critical_state(w)) ++rs.not_critical;
        if (uses_peak && peak_on_a_spike(row.r.metrics)) {
          ++rs.on_spike;
          ++p.spiked;
        }
      } else {
        ++p.missing;
      }
    } else if (st == "failed") {
      ++p.failed;
      p.invalid += row.r.task.error.rfind("invalid in stage ", 0) == 0;
    } else {
      ++p.unfinished;
    }
  }
}

}  // namespace

ResponseSurface gather(db::Store& store, const std::string& job, const std::string& metric,
                       const GatherOptions& opt) {
  const std::vector<Row> rows = read_rows(store, job, opt);
  ResponseSurface rs;
  rs.job = job;
  rs.metric = metric;
  const MetricSpec spec = metric_spec(metric);
  rs.label = spec.label;
  require_known_metric(store, job, metric, opt, rows);
  require_some_value(job, spec, opt, rows);
  require_one_grid(job, rows);
  std::map<NodeKey, std::size_t> index;
  std::set<double> thetas, etas;
  add_rows(rs, job, rows, spec, index, thetas, etas);
  // Nodes of the grid no task of this database stands on (the grid is the product of
  // its axes): holes, as the map draws them, not points silently left out.
  for (double th : thetas)
    for (double et : etas)
      if (!index.count(node_key(th, et))) {
        GridPoint p;
        p.theta = th;
        p.eta = et;
        p.absent = true;
        rs.points.push_back(p);
      }
  // Grid points first, then refinement points.
  std::stable_partition(rs.points.begin(), rs.points.end(), [](const GridPoint& p) { return !p.refine; });
  rs.thetas.assign(thetas.begin(), thetas.end());
  rs.etas.assign(etas.begin(), etas.end());
  rs.summarise();
  return rs;
}

}  // namespace demcal::calibrate
