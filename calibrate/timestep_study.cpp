// The timestep study: the seed's Fig. 2.6 collision test over dt factors (issue 9).
#include "study.hpp"
#include "study_support.hpp"


#include "engine/timestep.hpp"

#include <algorithm>
#include <map>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

namespace demcal::calibrate {
namespace fs = std::filesystem;
using namespace study_support;
namespace {

// Relative energy drift per simulated second the recommendation accepts: 10% of
// the energy per simulated second of this gas, in which friction and rolling
// dissipate about 170% per simulated second (so the integrator's error stays below
// a thousandth of the physical dissipation).
constexpr double kDefaultTolerance = 0.1;

nlohmann::json timestep_job(bool quick) {
  nlohmann::json j;
  j["name"] = quick ? "study-timestep-quick" : "study-timestep";
  j["description"] =
      "demcal study timestep: seed Fig. 2.6 collision test over dt factors, frictionless and with "
      "theta 30 deg, eta 0.1 (rolling active); equal simulated time per task";
  j["scene"] = "collision";
  j["material"] = {{"kn", 3e7}, {"ks", 2.7e7}, {"density", 2650.0}, {"b", 1.0}, {"theta_deg", 30.0},
                   {"eta", 0.1}, {"diameter", {{"min", 1e-3}, {"max", 2e-3}}}};
  j["collision"] = {{"particles", quick ? 150 : 1250},
                    {"solid_fraction", 0.2},
                    {"velocity_max", 1.0},
                    {"duration", quick ? 1e-3 : 4e-3},
                    {"allow_unstable_dt", true}};
  const std::vector<double> quick_k = {0.1, 0.3, 0.7, 1.4, 3.0};
  const std::vector<double> full_k = {0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8,
                                      0.9, 1.0, 1.2, 1.4, 1.6, 2.0, 2.5, 3.0};
  j["grid"] = {{"keep_friction", {false, true}}, {"dt_factor", quick ? quick_k : full_k}};
  j["replicas"] = quick ? 2 : 4;
  j["seed"] = 1;
  j["threads"] = 1;
  return j;
}

// Critical factors (limit / sqrt(m_min/Kn)) of the study's material.
void critical_factors(TimestepStudy& s) {
  engine::Material m;
  m.friction_angle = engine::deg_to_rad(30.0);
  m.rolling_eta = 0.1;
  engine::LimitInputs in;
  in.r_min = 0.5e-3;
  in.r_max = 1.0e-3;
  in.m_min = m.density * engine::sphere_volume(in.r_min);
  in.m_max = m.density * engine::sphere_volume(in.r_max);
  in.has_walls = true;  // the collision box: smooth walls
  in.law = engine::contact_params(m);
  const engine::StabilityLimits full = engine::stability_limits(in);
  s.critical_factor_full = full.governing().dt_critical / full.base_step;
  s.critical_mode_full = full.governing().mode + " (" + full.governing().contact + ")";
  in.law.ks = 0.0;  // the scene drops the tangential spring without friction
  in.law.eta = 0.0;
  const engine::StabilityLimits nofric = engine::stability_limits(in);
  s.critical_factor_frictionless = nofric.governing().dt_critical / nofric.base_step;
}

void mark_pareto(std::vector<TimestepPoint>& pts) {
  // Frictionless only: with friction the drift is mostly physical dissipation, not error.
  for (auto& p : pts) {
    if (!p.ok || p.friction) continue;
    p.pareto = true;
    for (const auto& q : pts) {
      if (&q == &p || !q.ok || q.friction != p.friction) continue;
      const bool no_worse = q.cost <= p.cost && std::abs(q.drift) <= std::abs(p.drift);
      const bool better = q.cost < p.cost || std::abs(q.drift) < std::abs(p.drift);
      if (no_worse && better) {
        p.pareto = false;
        break;
      }
    }
  }
}

// One row per point: its status and failure, and nan for what a failed point lacks.
void write_timestep_csv(const TimestepStudy& s, const fs::path& csv) {
  WholeTextFile c(csv);
  c << "series,dt_factor,dt,status,failure,drift_per_simulated_s,max_relative_error,wall_s_per_simulated_s,pareto,error,"
       "replicas,drift_mean,drift_sd\n";
  for (const auto& p : s.points) {
    // A failed point has no drift, error or cost to give: nan, not a 0 that reads as exact.
    const auto v = [&](double x) { return p.ok ? fmt(x, 6) : std::string("nan"); };
    c << (p.friction ? "friction_rolling" : "frictionless") << "," << p.dt_factor << "," << v(p.dt) << ","
      << timestep_status(p, s) << "," << (timestep_failed(p, s.tolerance) ? 1 : 0) << "," << v(p.drift) << ","
      << v(p.max_relative_error) << "," << v(p.cost) << "," << (p.pareto ? 1 : 0) << ",\"" << p.error.substr(0, 120)
      << "\"," << p.replicas << "," << v(p.drift_mean) << "," << v(p.drift_sd) << "\n";
  }
  c.commit();
}

// gnuplot data blocks: 0 frictionless ok, 1 friction ok, 2 frictionless failed (drawn
// at `ceiling`), 3 friction failed, 4 frictionless Pareto (by cost), 5 friction Pareto.
void write_timestep_data(const TimestepStudy& s, const fs::path& data, double ceiling) {
  const double floor_v = 1e-9;
  std::ofstream d(data);
  d.precision(8);
  for (int block = 0; block < 6; ++block) {
    const bool fric = block % 2 == 1;
    std::vector<TimestepPoint> sel;
    for (const auto& p : s.points) {
      if (p.friction != fric) continue;
      if (block < 2 && p.ok) sel.push_back(p);
      if (block >= 2 && block < 4 && !p.ok) sel.push_back(p);
      if (block >= 4 && p.pareto) sel.push_back(p);
    }
    if (block >= 4) std::sort(sel.begin(), sel.end(), [](auto& a, auto& b) { return a.cost < b.cost; });
    d << "# block " << block << "\n";
    for (const auto& p : sel)
      d << p.dt_factor << " " << (p.ok ? std::max(floor_v, std::abs(p.drift)) : ceiling) << " " << p.cost << "\n";
    if (sel.empty()) d << "nan nan nan\n";
    d << "\n\n";
  }
}

// Two charts: drift against the step factor (failure region from `first_fail`, the
// critical factors, the tolerance, the recommendation), and drift against cost.
void write_timestep_script(const TimestepStudy& s, const fs::path& data, const fs::path& script,
                           const std::string& drift_part, const std::string& cost_part, double ceiling,
                           double first_fail) {
  const std::string dq = gnuplot_quoted(data.string());
  std::ofstream g(script);
  g << gnuplot_png_terminal(1000, 720) << "set output " << gnuplot_quoted(drift_part) << "\n"
    << "set title 'Collision test (seed Fig. 2.6): energy drift against the time-step factor' noenhanced\n"
    << "set xlabel 'dt factor k  (dt = k sqrt(m_min / Kn))' noenhanced\n"
    << "set ylabel '|relative energy drift| per simulated second, worst of the replicas' noenhanced\n"
    << "set logscale xy\nset grid\nset key below box noenhanced\n"
    << "set xrange [" << s.points.front().dt_factor * 0.8 << ":" << s.points.back().dt_factor * 1.25 << "]\n"
    << "set yrange [*:" << ceiling * 3 << "]\n";
  if (first_fail < 1e300)
    g << "set object 1 rect from " << first_fail * 0.97 << ", graph 0 to graph 1, graph 1 fc rgb '#ffd8d8' "
      << "fs solid 0.6 noborder behind\n"
      << "set label 1 'failure region' at " << first_fail << ", graph 0.93 offset 1,0 tc rgb '#b00000'\n";
  g << "set arrow 1 from " << s.critical_factor_frictionless << ", graph 0 to " << s.critical_factor_frictionless
    << ", graph 1 nohead dt 2 lw 2 lc rgb '#1f77b4'\n"
    << "set label 2 'critical, normal mode (" << fmt(s.critical_factor_frictionless) << ")' at "
    << s.critical_factor_frictionless << ", graph 0.06 rotate by 90 offset -1,0 tc rgb '#1f77b4'\n"
    << "set arrow 2 from " << s.critical_factor_full << ", graph 0 to " << s.critical_factor_full
    << ", graph 1 nohead dt 2 lw 2 lc rgb '#d62728'\n"
    << "set label 3 'critical, " << s.critical_mode_full << " (" << fmt(s.critical_factor_full) << ")' at "
    << s.critical_factor_full << ", graph 0.06 rotate by 90 offset -1,0 tc rgb '#d62728' noenhanced\n"
    << "set arrow 3 from graph 0, first " << s.tolerance << " to graph 1, first " << s.tolerance
    << " nohead dt 3 lc rgb '#2ca02c'\n"
    << "set label 4 'tolerance " << fmt(s.tolerance) << "' at graph 0.02, first " << s.tolerance * 1.5
    << " tc rgb '#2ca02c'\n";
  if (s.recommended_factor > 0)
    g << "set arrow 4 from " << s.recommended_factor << ", graph 0 to " << s.recommended_factor
      << ", graph 0.8 nohead lw 2 lc rgb '#2ca02c'\n"
      << "set label 5 'recommended k = " << fmt(s.recommended_factor) << "' at " << s.recommended_factor
      << ", graph 0.82 center tc rgb '#2ca02c'\n";
  g << "plot " << dq << " index 0 using 1:2 with linespoints pt 7 lc rgb '#1f77b4' title 'frictionless', "
    << dq << " index 1 using 1:2 with linespoints pt 5 lc rgb '#d62728' title 'theta 30 deg, eta 0.1 (rolling on): dissipates; least-dissipating replica', "
    << dq << " index 2 using 1:2 with points pt 2 ps 2 lc rgb '#1f77b4' title 'frictionless: unstable', "
    << dq << " index 3 using 1:2 with points pt 3 ps 2 lc rgb '#d62728' title 'rolling on: unstable'\n";
  g << "reset\n" << gnuplot_png_terminal(1000, 720) << "set output " << gnuplot_quoted(cost_part) << "\n"
    << "set title 'Collision test: accuracy against cost (stable runs; Pareto front joined)' noenhanced\n"
    << "set xlabel 'wall seconds per simulated second (one core, contended machine)' noenhanced\n"
    << "set ylabel '|relative energy drift| per simulated second, worst of the replicas' noenhanced\n"
    << "set logscale xy\nset grid\nset key below box noenhanced\n"
    << "set arrow 3 from graph 0, first " << s.tolerance << " to graph 1, first " << s.tolerance
    << " nohead dt 3 lc rgb '#2ca02c'\n"
    << "plot " << dq << " index 0 using 3:2:(sprintf('%g', $1)) with labels offset 1.5,0.6 font ',8' tc rgb '#1f77b4' notitle, "
    << dq << " index 0 using 3:2 with points pt 7 lc rgb '#1f77b4' title 'frictionless (labels: k)', "
    << dq << " index 4 using 3:2 with lines lw 2 lc rgb '#1f77b4' title 'frictionless Pareto front', "
    << dq << " index 1 using 3:2 with points pt 5 lc rgb '#d62728' title 'rolling on (drift = dissipation, not error)'\n";
}

void write_timestep_charts(TimestepStudy& s, const fs::path& dir) {
  double top = 1.0;
  for (const auto& p : s.points)
    if (p.ok) top = std::max(top, std::abs(p.drift));
  const double ceiling = top * 30.0;  // failed runs are drawn here
  double first_fail = 1e300;
  for (const auto& p : s.points)
    if (timestep_failed(p, s.tolerance)) first_fail = std::min(first_fail, p.dt_factor);

  const fs::path csv = dir / "timestep.csv";
  write_timestep_csv(s, csv);
  s.files.push_back(csv.string());
  const fs::path data = dir / "timestep.dat";
  write_timestep_data(s, data, ceiling);
  const fs::path drift_png = dir / "timestep_drift.png", cost_png = dir / "timestep_cost.png";
  const fs::path script = dir / "timestep.gp";
  ImageFile drift_image(drift_png.string()), cost_image(cost_png.string());
  write_timestep_script(s, data, script, drift_image.part(), cost_image.part(), ceiling, first_fail);
  run_gnuplot_script(script.string());
  drift_image.commit();
  cost_image.commit();
  keep_script_redrawable(script.string(), dir.string(),
                         {{drift_image.part(), drift_png.string()}, {cost_image.part(), cost_png.string()}});
  s.files.push_back(drift_png.string());
  s.files.push_back(cost_png.string());
}

}  // namespace

// Friction and rolling dissipate, so only a gain counts there; without friction any
// drift of either sign is error, but a loss that large is failure too.
bool timestep_failed(const TimestepPoint& p, double tol) {
  if (!p.ok) return true;
  return p.friction ? p.drift > kTimestepExplode * tol : std::abs(p.drift) > kTimestepExplode * tol;
}

std::string timestep_status(const TimestepPoint& p, const TimestepStudy& s) {
  if (!p.ok) return "unstable";
  if (timestep_failed(p, s.tolerance)) return "failed";
  const double critical = p.friction ? s.critical_factor_full : s.critical_factor_frictionless;
  return critical > 0.0 && p.dt_factor > critical * (1.0 + 1e-9) ? "ran*" : "ok";
}

// One factor of one series over its replicas: failed if any replica failed; else the
// worst replica's drift (what the recommendation judges), the mean and spread beside it.
TimestepPoint timestep_point(bool friction, double factor, const std::vector<ResultRow>& rows) {
  TimestepPoint p;
  p.friction = friction;
  p.dt_factor = factor;
  p.replicas = static_cast<int>(rows.size());
  p.ok = !rows.empty();
  std::vector<double> drifts;
  for (const ResultRow& r : rows) {
    const double drift = r.task.status == "done" ? metric(r, "drift_per_simulated_s") : NAN;
    if (!std::isfinite(drift)) {
      p.ok = false;
      if (p.error.empty()) p.error = r.task.error.empty() ? "drift not finite" : r.task.error;
      continue;
    }
    drifts.push_back(drift);
    p.dt += metric(r, "dt");
    p.max_relative_error = std::max(p.max_relative_error, metric(r, "max_relative_error"));
    p.cost += metric(r, "wall_s_per_simulated_s") / static_cast<double>(rows.size());
  }
  if (!drifts.empty()) p.dt /= static_cast<double>(drifts.size());
  if (!p.ok || drifts.empty()) return p;
  p.drift = drifts.front();
  for (double d : drifts) {
    p.drift_mean += d / static_cast<double>(drifts.size());
    if (friction ? d > p.drift : std::abs(d) > std::abs(p.drift)) p.drift = d;
  }
  for (double d : drifts)
    p.drift_sd += drifts.size() > 1 ? (d - p.drift_mean) * (d - p.drift_mean) / static_cast<double>(drifts.size() - 1) : 0.0;
  p.drift_sd = std::sqrt(p.drift_sd);
  return p;
}

namespace {

// Runs (or resumes) the study's job; the study needs every task finished.
void run_study_tasks(db::Store& store, const Job& job, const StudyOptions& o, TimestepStudy& s) {
  fs::create_directories(o.out_dir);
  RunOptions ro;
  ro.workers = o.workers;
  ro.out_dir = (fs::path(o.out_dir) / "tasks").string();
  ro.terminal = o.terminal;
  ro.log = o.log;
  const RunSummary sum = run_job(store, job, ro);
  if (sum.interrupted) throw std::runtime_error("study interrupted: finished tasks are kept, run it again to resume");
  jobs::throw_if_stopped_short(sum, "study " + job.name);
  if (sum.unfinished > 0) throw std::runtime_error("study: " + std::to_string(sum.unfinished) + " tasks unfinished");
  s.tasks = sum.total;
  s.reused = sum.reused;
  s.ran = sum.ran;
}

// One point per (friction, factor), its replicas pooled; frictionless first, each
// series by factor.
void collect_points(db::Store& store, const Job& job, TimestepStudy& s) {
  std::map<std::pair<bool, double>, std::vector<ResultRow>> groups;  // (friction, factor) -> replicas
  for (ResultRow& r : select_rows(store, job.name, {}))
    groups[{r.params.at("keep_friction").get<bool>(), r.params.at("dt_factor").get<double>()}].push_back(std::move(r));
  for (const auto& [key, rows] : groups) s.points.push_back(timestep_point(key.first, key.second, rows));
  std::sort(s.points.begin(), s.points.end(), [](auto& a, auto& b) {
    return a.friction != b.friction ? !a.friction : a.dt_factor < b.dt_factor;
  });
  mark_pareto(s.points);
}

// The run with friction and rolling at a frictionless point's factor (null: none).
const TimestepPoint* friction_run(const TimestepStudy& s, const TimestepPoint& p) {
  const auto it = std::find_if(s.points.begin(), s.points.end(),
                               [&](const TimestepPoint& q) { return q.friction && q.dt_factor == p.dt_factor; });
  return it == s.points.end() ? nullptr : &*it;
}

// Largest factor k such that at every factor up to k the frictionless drift is
// within tolerance and the run with friction and rolling neither went unstable nor
// gained more than the tolerance. Every smaller factor must pass too: one run per
// factor is noisy, and a lucky pass beyond a failure is no recommendation. Nor past
// the full law's critical step: the dilute gas's brief contacts may survive it, but
// the engine refuses it for a job, and a dense pack would not.
void recommend_factor(TimestepStudy& s) {
  for (const auto& p : s.points) {
    if (p.friction) continue;
    if (p.dt_factor > s.critical_factor_full) {
      s.capped_at_critical = s.recommended_factor > 0 && p.ok && std::abs(p.drift) <= s.tolerance;
      break;
    }
    const TimestepPoint* fr = friction_run(s, p);
    const bool pass = p.ok && std::abs(p.drift) <= s.tolerance && fr && fr->ok && fr->drift <= s.tolerance;
    if (!pass) break;  // points are sorted by factor within the series
    s.recommended_factor = p.dt_factor;
  }
}

// Why the smallest factor failed: every factor up to a recommendation must pass.
std::string why_none_passed(const TimestepStudy& s) {
  const auto p = std::find_if(s.points.begin(), s.points.end(), [](const TimestepPoint& q) { return !q.friction; });
  if (p == s.points.end()) return "no run finished";
  const TimestepPoint* fr = friction_run(s, *p);
  std::string why;
  if (!p->ok)
    why = "the frictionless runs went unstable";
  else if (std::abs(p->drift) > s.tolerance)
    why = "the frictionless runs drifted by " + fmt(p->drift, 3) + " per simulated second";
  else if (!fr || !fr->ok)
    why = "the runs with friction and rolling went unstable";
  else
    why = "the runs with friction and rolling gained " + fmt(fr->drift, 3) + " per simulated second";
  return "already at the smallest factor, " + fmt(p->dt_factor) + ", " + why;
}

std::string recommendation_text(const TimestepStudy& s) {
  std::ostringstream rec;
  if (s.recommended_factor <= 0) {
    rec << "no dt_factor passed at tolerance " << fmt(s.tolerance) << " per simulated second: " << why_none_passed(s)
        << " (a factor is recommended only if it and every smaller one pass)";
    return rec.str();
  }
  const double base = std::sqrt(2650.0 * engine::sphere_volume(0.5e-3) / 3e7);
  rec << "recommended dt_factor " << s.recommended_factor << " (dt = " << fmt(s.recommended_factor * base)
      << " s for d_min = 1 mm, Kn = 3e7 N/m): the largest factor whose energy drift stays within "
      << fmt(s.tolerance) << " per simulated second frictionless in every replica, at it and at every smaller factor, and "
      << "whose run with friction and rolling stays stable and gains no energy beyond it; the engine's critical factors are " << fmt(s.critical_factor_frictionless)
      << " (frictionless, normal mode) and " << fmt(s.critical_factor_full) << " (" << s.critical_mode_full
      << ")";
  if (s.capped_at_critical)
    rec << "; the next factor's frictionless runs drifted within the tolerance too, but it lies past the critical "
           "step of the full law, which the engine refuses for a job";
  return rec.str();
}

}  // namespace

TimestepStudy run_timestep_study(db::Store& store, const StudyOptions& o) {
  TimestepStudy s;
  s.tolerance = o.tolerance > 0 ? o.tolerance : kDefaultTolerance;
  const Job job = parse_job(timestep_job(o.quick).dump(2), "study timestep");
  s.job = job.name;
  run_study_tasks(store, job, o, s);
  critical_factors(s);
  collect_points(store, job, s);
  recommend_factor(s);
  s.recommendation = recommendation_text(s);
  write_timestep_charts(s, o.out_dir);
  const std::string text = (fs::path(o.out_dir) / "timestep_recommendation.txt").string();
  WholeTextFile r(text);
  r << s.recommendation << "\n";
  r.commit();
  s.files.push_back(text);
  return s;
}

}  // namespace demcal::calibrate
