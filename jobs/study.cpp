#include "study.hpp"

#include "job_error.hpp"
#include "job_spec.hpp"
#include "query.hpp"
#include "runner.hpp"
#include "series_plot.hpp"

#include "engine/scenes/grazing_impact.hpp"
#include "engine/timestep.hpp"

#include <algorithm>
#include <map>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

namespace demcal::jobs {
namespace fs = std::filesystem;
namespace {

// A study's tables, advice and job files are its result: a write that fails (disk
// full, a folder or a device in the way) is an error, not a "wrote" line.
void close_checked(std::ofstream& f, const std::string& path) {
  f.close();
  if (!f) throw std::runtime_error("cannot write " + path + " (disk full, or not a writable file)");
}


// Relative energy drift per simulated second the recommendation accepts: 10% of
// the energy per simulated second of this gas, in which friction and rolling
// dissipate about 170% per simulated second (so the integrator's error stays below
// a thousandth of the physical dissipation).
constexpr double kDefaultTolerance = 0.1;

double metric(const ResultRow& r, const std::string& name) {
  for (const auto& [k, v] : r.metrics)
    if (k == name) return v;
  return NAN;
}

std::string fmt(double v, int prec = 3) {
  std::ostringstream os;
  os << std::setprecision(prec) << v;
  return os.str();
}

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

// Where the method fails: the run went unstable (non-finite state, overlap or the
// scene's checks), or energy grew by more than kExplode tolerances per simulated
// second. Friction and rolling dissipate, so only a gain counts there; without
// friction any drift of either sign is error, but a loss that large is failure too.
constexpr double kExplode = 100.0;
bool failed(const TimestepPoint& p, double tol) {
  if (!p.ok) return true;
  return p.friction ? p.drift > kExplode * tol : std::abs(p.drift) > kExplode * tol;
}

void write_timestep_charts(TimestepStudy& s, const fs::path& dir) {
  const double floor_v = 1e-9;
  double top = 1.0;
  for (const auto& p : s.points)
    if (p.ok) top = std::max(top, std::abs(p.drift));
  const double ceiling = top * 30.0;  // failed runs are drawn here
  double first_fail = 1e300;
  for (const auto& p : s.points)
    if (failed(p, s.tolerance)) first_fail = std::min(first_fail, p.dt_factor);

  const fs::path csv = dir / "timestep.csv";
  {
    std::ofstream c(csv);
    c << "series,dt_factor,dt,status,failure,drift_per_simulated_s,max_relative_error,wall_s_per_simulated_s,pareto,error,"
         "replicas,drift_mean,drift_sd\n";
    for (const auto& p : s.points) {
      // A failed point has no drift, error or cost to give: nan, not a 0 that reads as exact.
      const auto v = [&](double x) { return p.ok ? fmt(x, 6) : std::string("nan"); };
      c << (p.friction ? "friction_rolling" : "frictionless") << "," << p.dt_factor << "," << v(p.dt) << ","
        << (p.ok ? "ok" : "unstable") << "," << (failed(p, s.tolerance) ? 1 : 0) << "," << v(p.drift) << ","
        << v(p.max_relative_error) << "," << v(p.cost) << "," << (p.pareto ? 1 : 0) << ",\"" << p.error.substr(0, 120)
        << "\"," << p.replicas << "," << v(p.drift_mean) << "," << v(p.drift_sd) << "\n";
    }
    close_checked(c, csv.string());
  }
  s.files.push_back(csv.string());

  // gnuplot data blocks: 0 frictionless ok, 1 friction ok, 2 frictionless failed,
  // 3 friction failed, 4 frictionless Pareto (by cost), 5 friction Pareto.
  const fs::path data = dir / "timestep.dat";
  {
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
  const std::string dq = gnuplot_quoted(data.string());
  const fs::path drift_png = dir / "timestep_drift.png", cost_png = dir / "timestep_cost.png";
  const fs::path script = dir / "timestep.gp";
  ImageFile drift_image(drift_png.string()), cost_image(cost_png.string());
  {
    std::ofstream g(script);
    g << gnuplot_png_terminal(1000, 720) << "set output " << gnuplot_quoted(drift_image.part()) << "\n"
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
    g << "reset\n" << gnuplot_png_terminal(1000, 720) << "set output " << gnuplot_quoted(cost_image.part()) << "\n"
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
  run_gnuplot_script(script.string());
  drift_image.commit();
  cost_image.commit();
  s.files.push_back(drift_png.string());
  s.files.push_back(cost_png.string());
}

}  // namespace

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
    p.dt = metric(r, "dt");
    p.max_relative_error = std::max(p.max_relative_error, metric(r, "max_relative_error"));
    p.cost += metric(r, "wall_s_per_simulated_s") / static_cast<double>(rows.size());
  }
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

const std::vector<std::string>& study_names() {
  static const std::vector<std::string> names = {"timestep", "grazing", "fidelity", "repose-fidelity"};
  return names;
}

TimestepStudy run_timestep_study(db::Store& store, const StudyOptions& o) {
  TimestepStudy s;
  s.tolerance = o.tolerance > 0 ? o.tolerance : kDefaultTolerance;
  const Job job = parse_job(timestep_job(o.quick).dump(2), "study timestep");
  s.job = job.name;
  fs::create_directories(o.out_dir);
  RunOptions ro;
  ro.workers = o.workers;
  ro.out_dir = (fs::path(o.out_dir) / "tasks").string();
  ro.terminal = o.terminal;
  ro.log = o.log;
  const RunSummary sum = run_job(store, job, ro);
  if (sum.interrupted) throw std::runtime_error("study interrupted: finished tasks are kept, run it again to resume");
  if (sum.unfinished > 0) throw std::runtime_error("study: " + std::to_string(sum.unfinished) + " tasks unfinished");
  s.tasks = sum.total;
  s.reused = sum.reused;
  s.ran = sum.ran;

  critical_factors(s);
  std::map<std::pair<bool, double>, std::vector<ResultRow>> groups;  // (friction, factor) -> replicas
  for (ResultRow& r : select_rows(store, job.name, {}))
    groups[{r.params.at("keep_friction").get<bool>(), r.params.at("dt_factor").get<double>()}].push_back(std::move(r));
  for (const auto& [key, rows] : groups) s.points.push_back(timestep_point(key.first, key.second, rows));
  std::sort(s.points.begin(), s.points.end(), [](auto& a, auto& b) {
    return a.friction != b.friction ? !a.friction : a.dt_factor < b.dt_factor;
  });
  mark_pareto(s.points);

  // Largest factor k such that at every factor up to k the frictionless drift is
  // within tolerance and the run with friction and rolling neither went unstable nor
  // gained more than the tolerance. Every smaller factor must pass too: one run per
  // factor is noisy, and a lucky pass beyond a failure is no recommendation.
  for (const auto& p : s.points) {
    if (p.friction) continue;
    const auto fr = std::find_if(s.points.begin(), s.points.end(),
                                 [&](const TimestepPoint& q) { return q.friction && q.dt_factor == p.dt_factor; });
    const bool pass = p.ok && std::abs(p.drift) <= s.tolerance && fr != s.points.end() && fr->ok &&
                      fr->drift <= s.tolerance;
    if (!pass) break;  // points are sorted by factor within the series
    s.recommended_factor = p.dt_factor;
  }
  std::ostringstream rec;
  if (s.recommended_factor > 0) {
    const double base = std::sqrt(2650.0 * engine::sphere_volume(0.5e-3) / 3e7);
    rec << "recommended dt_factor " << s.recommended_factor << " (dt = " << fmt(s.recommended_factor * base)
        << " s for d_min = 1 mm, Kn = 3e7 N/m): the largest factor whose energy drift stays within "
        << fmt(s.tolerance) << " per simulated second frictionless in every replica, at it and at every smaller factor, and "
        << "whose run with friction and rolling stays stable and gains no energy beyond it; the engine's critical factors are " << fmt(s.critical_factor_frictionless)
        << " (frictionless, normal mode) and " << fmt(s.critical_factor_full) << " (" << s.critical_mode_full
        << ")";
  } else {
    rec << "no dt_factor passed: every factor drifted by more than " << fmt(s.tolerance)
        << " per simulated second or went unstable";
  }
  s.recommendation = rec.str();
  write_timestep_charts(s, o.out_dir);
  {
    std::ofstream r(fs::path(o.out_dir) / "timestep_recommendation.txt");
    r << s.recommendation << "\n";
    close_checked(r, (fs::path(o.out_dir) / "timestep_recommendation.txt").string());
    s.files.push_back((fs::path(o.out_dir) / "timestep_recommendation.txt").string());
  }
  return s;
}

GrazingStudy run_grazing_study(const StudyOptions& o) {
  GrazingStudy s;
  fs::create_directories(o.out_dir);
  std::vector<double> angles;
  for (double a = 5.0; a <= 85.0; a += o.quick ? 20.0 : 2.5) angles.push_back(a);
  const std::vector<double> fractions = o.quick ? std::vector<double>{0.1} : std::vector<double>{0.1, 0.01};
  const engine::ImpactTarget targets[] = {engine::ImpactTarget::wall, engine::ImpactTarget::fixed_sphere,
                                          engine::ImpactTarget::free_sphere};
  s.worst_gain = -1.0;
  for (double f : fractions) {
    for (auto t : targets) {
      engine::GrazingConfig c;
      c.target = t;
      c.dt_fraction = f;
      for (const auto& r : engine::sweep_grazing(c, angles)) {
        if (!r.outcome.ok())
          throw std::runtime_error(std::string("grazing impact on ") + engine::to_string(t) + " at " +
                                   fmt(r.incidence_deg) + " deg failed: " + r.outcome.message);
        s.rows.push_back({engine::to_string(t), r.incidence_deg, f, r.energy_ratio, r.max_energy_ratio,
                          r.rebound_deg, r.slid});
        if (r.energy_ratio - 1.0 > s.worst_gain) {
          s.worst_gain = r.energy_ratio - 1.0;
          s.worst_where = std::string(engine::to_string(t)) + " at " + fmt(r.incidence_deg) + " deg, dt = " +
                          fmt(f) + " t_c";
        }
      }
    }
  }
  const fs::path dir = o.out_dir;
  const fs::path csv = dir / "grazing.csv", data = dir / "grazing.dat", script = dir / "grazing.gp",
                 png = dir / "grazing_energy.png";
  ImageFile image(png.string());
  {
    std::ofstream c(csv);
    c.precision(10);
    c << "target,incidence_deg,dt_over_tc,energy_ratio,max_energy_ratio,rebound_deg,slid\n";
    for (const auto& r : s.rows)
      c << r.target << "," << r.incidence_deg << "," << r.dt_fraction << "," << r.energy_ratio << ","
        << r.max_energy_ratio << "," << r.rebound_deg << "," << (r.slid ? 1 : 0) << "\n";
    close_checked(c, csv.string());
    std::ofstream d(data);
    d.precision(10);
    for (double f : fractions)
      for (auto t : targets) {
        d << "# " << engine::to_string(t) << " dt " << f << "\n";
        for (const auto& r : s.rows)
          if (r.target == engine::to_string(t) && r.dt_fraction == f)
            d << r.incidence_deg << " " << r.energy_ratio << " " << r.rebound_deg << "\n";
        d << "\n\n";
      }
    std::ofstream g(script);
    const std::string dq = gnuplot_quoted(data.string());
    g << gnuplot_png_terminal(1000, 720) << "set output " << gnuplot_quoted(image.part()) << "\n"
      << "set title 'Grazing impact, theta 30 deg, eta 0.1, b 1, no damping: energy after / before' noenhanced\n"
      << "set xlabel 'incidence angle from the contact normal [deg] (90 = grazing)' noenhanced\n"
      << "set ylabel 'E_after / E_before (kinetic + rotational + elastic)' noenhanced\n"
      << "set y2label 'rebound angle [deg]' noenhanced\nset y2tics\nset ytics nomirror\n"
      << "set grid\nset key below box noenhanced\nset xrange [0:90]\n"
      << "set arrow 1 from graph 0, first 1 to graph 1, first 1 nohead lw 2 lc rgb 'black'\n";
    const char* colours[] = {"#1f77b4", "#d62728", "#2ca02c"};
    g << "plot ";
    int idx = 0;
    bool first = true;
    for (double f : fractions)
      for (int t = 0; t < 3; ++t, ++idx) {
        g << (first ? "" : ", ") << dq << " index " << idx << " using 1:2 with linespoints pt " << (f == fractions[0] ? 7 : 6)
          << " lc rgb '" << colours[t] << "'" << (f == fractions[0] ? "" : " dt 2") << " title '"
          << engine::to_string(targets[t]) << ", dt = " << fmt(f) << " t_c'";
        first = false;
        if (f == fractions[0])
          g << ", " << dq << " index " << idx << " using 1:3 axes x1y2 with lines lw 1 dt 3 lc rgb '" << colours[t]
            << "' title '" << engine::to_string(targets[t]) << ": rebound angle (right axis)'";
      }
    g << "\n";
  }
  run_gnuplot_script(script.string());
  image.commit();
  s.files = {csv.string(), png.string()};
  return s;
}

// ---------------------------------------------------------------------------
// Fidelity studies (issue 9): one knob at a time around a baseline.
namespace {

struct KnobDef {
  std::string name;
  std::vector<std::string> aliases;   // also accepted by --knobs / --reference
  std::vector<std::string> params;    // each setting sets all of these to its value
  std::string what;                   // axis words
  std::vector<nlohmann::json> values; // settings (the baseline's value among them)
  double reference = 0;               // the most expensive setting
};

struct FidelityDef {
  std::string name, scene;
  nlohmann::json material, base;      // base: the scene section at the baseline
  std::vector<std::string> metrics;   // error metrics
  std::vector<KnobDef> knobs;
};

nlohmann::json seed_material() {
  return {{"kn", 3e7}, {"ks", 2.7e7}, {"density", 2650.0}, {"b", 1.0}, {"theta_deg", 30.0}, {"eta", 0.1},
          {"diameter", {{"min", 1e-3}, {"max", 2e-3}}}};
}

FidelityDef fidelity_def(const std::string& name, bool quick) {
  FidelityDef d;
  d.name = name;
  d.material = seed_material();
  if (name == "fidelity") {
    d.scene = "triaxial";
    d.metrics = {"phi_peak_deg", "phi_cv_deg"};
    // The baseline is the seed study's (examples/seed-study): dense, 100 kPa,
    // theta 30 deg, eta 0.1, 500 grains, 3e-4 /s, so its tasks are shared with it.
    if (!quick) {
      d.base = {{"packing", "dense"}, {"confining_kpa", 100.0}, {"axial_strain", 0.3}, {"particles", 500},
                {"strain_rate", 3e-4}, {"dt_factor", 0.3}, {"scaled_density", 2.65e12}};
      d.knobs = {{"particles", {}, {"particles"}, "particle count", {250, 500, 1000, 2000}, 2000},
                 {"rate", {"strain_rate"}, {"strain_rate"}, "axial strain rate [1/s]", {1e-4, 3e-4, 1e-3}, 1e-4},
                 {"dt", {"dt_factor"}, {"dt_factor"}, "dt factor", {0.15, 0.3, 0.45}, 0.15},
                 {"density", {"scaled_density", "density_scale"}, {"scaled_density"}, "scaled grain density [kg/m^3]",
                  {2.65e11, 2.65e12, 2.65e13}, 2.65e11}};
    } else {
      // A smoke-sized version: 150-300 grains to 10% axial strain at 1e-2 /s
      // (inertial, not quasi-static: its figures check the machinery, not the physics).
      d.base = {{"packing", "dense"}, {"confining_kpa", 100.0}, {"axial_strain", 0.1}, {"particles", 150},
                {"strain_rate", 1e-2}, {"dt_factor", 0.3}, {"scaled_density", 2.65e12}};
      d.knobs = {{"particles", {}, {"particles"}, "particle count", {150, 300}, 300},
                 {"rate", {"strain_rate"}, {"strain_rate"}, "axial strain rate [1/s]", {3e-3, 1e-2}, 3e-3},
                 // 2.0 is past the engine's critical step (rolling mode, ~0.72): it fails at
                 // once, so the quick study always shows how failures are charted and listed.
                 {"dt", {"dt_factor"}, {"dt_factor"}, "dt factor", {0.15, 0.3, 2.0}, 0.15},
                 {"density", {"scaled_density", "density_scale"}, {"scaled_density"}, "scaled grain density [kg/m^3]",
                  {2.65e12, 2.65e13}, 2.65e12}};
    }
  } else {
    d.scene = "repose";
    d.metrics = {"repose_deg"};
    // Baseline: the standard preset (the seed's 50 mm column, 4 d slab, 1e-3
    // stiffness, the engine's dt factor) with a 3 s time limit for the larger columns.
    // The slab needs at least ~2.8 d (periodic images must not interact), so depth
    // starts at 3.
    if (!quick) {
      d.base = {{"column_width", 0.05}, {"column_height", 0.05}, {"depth_diameters", 4.0}, {"stiffness_scale", 1e-3},
                {"dt_factor", 0.465}, {"time_limit", 3.0}};
      d.knobs = {{"depth", {"depth_diameters"}, {"depth_diameters"}, "slab depth [d_mean]", {3.0, 4.0, 6.0}, 6.0},
                 {"column", {"column_width", "column_height", "particles"}, {"column_width", "column_height"},
                  "column width = height [m]", {0.03, 0.05, 0.07}, 0.07},
                 {"stiffness", {"stiffness_scale"}, {"stiffness_scale"}, "stiffness scale", {1e-4, 1e-3, 1e-2}, 1e-2},
                 {"dt", {"dt_factor"}, {"dt_factor"}, "dt factor", {0.15, 0.3, 0.465}, 0.15}};
    } else {
      // A smoke-sized version: a 15 mm column of ~250 grains at 1e-4 stiffness.
      d.base = {{"column_width", 0.015}, {"column_height", 0.015}, {"depth_diameters", 3.0}, {"stiffness_scale", 1e-4},
                {"dt_factor", 0.465}, {"time_limit", 2.0}};
      d.knobs = {{"depth", {"depth_diameters"}, {"depth_diameters"}, "slab depth [d_mean]", {3.0, 4.0}, 4.0},
                 {"column", {"column_width", "column_height", "particles"}, {"column_width", "column_height"},
                  "column width = height [m]", {0.015, 0.02}, 0.02},
                 {"stiffness", {"stiffness_scale"}, {"stiffness_scale"}, "stiffness scale", {1e-4, 1e-3}, 1e-3},
                 {"dt", {"dt_factor"}, {"dt_factor"}, "dt factor", {0.3, 0.465}, 0.3}};
    }
  }
  return d;
}

const KnobDef* find_knob(const FidelityDef& d, const std::string& name) {
  for (const auto& k : d.knobs) {
    if (k.name == name) return &k;
    for (const auto& a : k.aliases)
      if (a == name) return &k;
  }
  return nullptr;
}

std::string knob_list(const FidelityDef& d) {
  std::string all;
  for (const auto& k : d.knobs) all += (all.empty() ? "" : ", ") + k.name;
  return all;
}

bool same_value(double a, double b) { return std::abs(a - b) <= 1e-9 * std::max(std::abs(a), std::abs(b)); }

std::string label_of(double v) { return fmt(v, 4); }

// The knobs selected, in the study's order, each with its reference (given or default).
std::vector<KnobDef> selected_knobs(const FidelityDef& d, const StudyOptions& o) {
  for (const auto& [k, v] : o.reference) {
    const KnobDef* def = find_knob(d, k);
    if (!def)
      throw JobError("--reference", "unknown knob \"" + k + "\" for study " + d.name + " (expected one of: " +
                                        knob_list(d) + ")");
    if (!(v > 0) || !std::isfinite(v))
      throw JobError("--reference", "the reference for " + def->name + " must be a positive number");
    // Two names of one knob (rate and strain_rate): which one would count is not the user's to guess.
    for (const auto& [k2, v2] : o.reference)
      if (k2 < k && find_knob(d, k2) == def)
        throw JobError("--reference", k2 + " and " + k + " both name the knob " + def->name + "; give one reference");
  }
  std::vector<std::string> want;
  for (const auto& n : o.knobs) {
    const KnobDef* def = find_knob(d, n);
    if (!def)
      throw JobError("--knobs", "unknown knob \"" + n + "\" for study " + d.name + " (expected one of: " +
                                    knob_list(d) + ")");
    want.push_back(def->name);
  }
  // A reference for a knob the study leaves out would be ignored without a word.
  for (const auto& [k, v] : o.reference)
    if (!want.empty() && std::find(want.begin(), want.end(), find_knob(d, k)->name) == want.end())
      throw JobError("--reference", k + " is not among the knobs this study varies (--knobs)");
  std::vector<KnobDef> out;
  for (KnobDef k : d.knobs) {
    if (!want.empty() && std::find(want.begin(), want.end(), k.name) == want.end()) continue;
    for (const auto& [name, v] : o.reference) {
      if (find_knob(d, name) != find_knob(d, k.name)) continue;
      k.reference = v;
      const bool have = std::any_of(k.values.begin(), k.values.end(),
                                    [&](const nlohmann::json& x) { return same_value(x.get<double>(), v); });
      if (!have) {
        if (k.params.front() == "particles") {
          if (v != std::floor(v)) throw JobError("--reference", "particles must be a whole number");
          k.values.push_back(static_cast<std::int64_t>(v));
        } else {
          k.values.push_back(v);
        }
      }
    }
    std::sort(k.values.begin(), k.values.end(),
              [](const nlohmann::json& a, const nlohmann::json& b) { return a.get<double>() < b.get<double>(); });
    out.push_back(k);
  }
  return out;
}

int effective_replicas(const StudyOptions& o) { return o.replicas > 0 ? o.replicas : (o.quick ? 1 : 3); }

std::string job_prefix(const FidelityDef& d, bool quick) { return "study-" + d.name + (quick ? "-quick" : ""); }

nlohmann::json base_job(const FidelityDef& d, const std::string& name, int replicas, const std::string& what) {
  nlohmann::json j;
  j["name"] = name;
  j["description"] = "demcal study " + d.name + ": " + what + ", one knob at a time around the baseline (written by the study; `demcal run` reruns it)";
  j["scene"] = d.scene;
  j["material"] = d.material;
  j[d.scene] = d.base;
  j["replicas"] = replicas;
  j["seed"] = 1;
  j["threads"] = 1;
  return j;
}

// One job per knob (the knob a grid axis), or one per setting when a setting sets
// several parameters (the grid is a Cartesian product).
std::vector<nlohmann::json> knob_jobs(const FidelityDef& d, const KnobDef& k, bool quick, int replicas) {
  std::vector<nlohmann::json> jobs;
  const std::string prefix = job_prefix(d, quick) + "-" + k.name;
  if (k.params.size() == 1) {
    nlohmann::json j = base_job(d, prefix, replicas, k.what);
    j[d.scene].erase(k.params.front());
    j["grid"] = {{k.params.front(), k.values}};
    jobs.push_back(j);
  } else {
    for (const auto& v : k.values) {
      nlohmann::json j = base_job(d, prefix + "-" + label_of(v.get<double>()), replicas, k.what + " = " + label_of(v.get<double>()));
      for (const auto& p : k.params) j[d.scene][p] = v;
      jobs.push_back(j);
    }
  }
  return jobs;
}

void mark_fidelity_pareto(std::vector<FidelityPoint>& pts) {
  for (auto& p : pts) {
    if (!std::isfinite(p.score) || p.failed > 0) continue;
    p.pareto = true;
    for (const auto& q : pts) {
      if (&q == &p || !std::isfinite(q.score) || q.failed > 0) continue;
      if (q.work <= p.work && q.score <= p.score && (q.work < p.work || q.score < p.score)) {
        p.pareto = false;
        break;
      }
    }
  }
}

std::string short_metric(const std::string& m) {
  if (m == "phi_peak_deg") return "phi_peak";
  if (m == "phi_cv_deg") return "phi_cv";
  if (m == "repose_deg") return "repose angle";
  return m;
}

void write_fidelity_chart(const FidelityStudy& s, FidelityKnob& k, const fs::path& dir) {
  double wmin = 1e300, wmax = 0, top = s.tolerance * 1.5;
  for (const auto& p : k.points) {
    if (std::isfinite(p.wall_s) && p.wall_s > 0) {
      wmin = std::min(wmin, p.wall_s);
      wmax = std::max(wmax, p.wall_s);
    }
    for (std::size_t m = 0; m < s.metrics.size(); ++m)
      if (std::isfinite(p.error[m])) top = std::max(top, p.error[m] + p.sd[m]);
  }
  if (wmax <= 0) wmin = wmax = 1.0;
  const double ceiling = top * 1.15;  // failed points are drawn here
  const std::string stem = s.name + "_" + k.name;
  const fs::path data = dir / (stem + ".dat"), script = dir / (stem + ".gp"), png = dir / (stem + ".png");
  // Blocks: 0 settings with an error (wall, then error and sd per metric, label),
  // 1 Pareto front by wall time, 2 failed settings, 3 the recommended setting.
  {
    std::ofstream f(data);
    f.precision(8);
    const auto quoted = [](const FidelityPoint& p) {
      return "\"" + p.label + (p.reference ? " (ref)" : "") + (p.failed > 0 && p.failed < p.replicas ? " (" +
             std::to_string(p.failed) + "/" + std::to_string(p.replicas) + " failed)" : "") + "\"";
    };
    f << "# block 0: wall_s, per metric error and replica sd, label\n";
    int n = 0;
    for (const auto& p : k.points) {
      if (!std::isfinite(p.score)) continue;
      f << p.wall_s;
      for (std::size_t m = 0; m < s.metrics.size(); ++m) f << " " << p.error[m] << " " << p.sd[m];
      f << " " << quoted(p) << "\n";
      ++n;
    }
    if (n == 0) {
      f << "nan";
      for (std::size_t m = 0; m < s.metrics.size(); ++m) f << " nan nan";
      f << " \"\"\n";
    }
    f << "\n\n# block 1: Pareto front (wall_s, max error + sd)\n";
    std::vector<FidelityPoint> front;
    for (const auto& p : k.points)
      if (p.pareto) front.push_back(p);
    std::sort(front.begin(), front.end(), [](auto& a, auto& b) { return a.wall_s < b.wall_s; });
    for (const auto& p : front) f << p.wall_s << " " << p.score << "\n";
    if (front.empty()) f << "nan nan\n";
    f << "\n\n# block 2: failed settings (every replica failed, or no reference)\n";
    n = 0;
    for (const auto& p : k.points) {
      if (std::isfinite(p.score)) continue;
      f << (std::isfinite(p.wall_s) && p.wall_s > 0 ? p.wall_s : wmin) << " " << ceiling << " \"" << p.label
        << (p.reference ? " (ref)" : "") << ": "
        << (p.failed > 0 ? std::to_string(p.failed) + "/" + std::to_string(p.replicas) + " failed" : "no error (reference failed)")
        << "\"\n";
      ++n;
    }
    if (n == 0) f << "nan nan \"\"\n";
    f << "\n\n# block 3: recommended\n";
    n = 0;
    for (const auto& p : k.points)
      if (p.recommended) {
        f << p.wall_s << " " << p.score << "\n";
        ++n;
      }
    if (n == 0) f << "nan nan\n";
  }
  const std::string dq = gnuplot_quoted(data.string());
  const int label_col = 2 + 2 * static_cast<int>(s.metrics.size());
  ImageFile image(png.string());
  {
    std::ofstream g(script);
    g << gnuplot_png_terminal(1000, 720) << "set output " << gnuplot_quoted(image.part()) << "\n"
      << "set title " << gnuplot_quoted("demcal study " + s.name + ": " + k.what + " against wall time (" +
                                        std::to_string(s.replicas) + " replicas per setting)") << " noenhanced\n"
      << "set xlabel 'wall seconds per task (engine, one thread; mean over replicas)' noenhanced\n"
      << "set ylabel '|metric - reference| [deg]; bars: replica standard deviation' noenhanced\n"
      << "set logscale x\nset grid\nset key below box noenhanced\n"
      << "set xrange [" << wmin / 1.6 << ":" << wmax * 1.6 << "]\nset yrange [" << -0.05 * ceiling << ":" << ceiling * 1.12 << "]\n"
      << "set arrow 1 from graph 0, first " << s.tolerance << " to graph 1, first " << s.tolerance
      << " nohead dt 3 lw 2 lc rgb '#2ca02c'\n"
      << "set label 1 'tolerance " << fmt(s.tolerance) << " deg' at graph 0.01, first " << s.tolerance
      << " offset 0,0.7 tc rgb '#2ca02c'\n"
      ;
    if (std::any_of(k.points.begin(), k.points.end(), [](const FidelityPoint& p) { return !std::isfinite(p.score); }))
      g << "set arrow 2 from graph 0, first " << ceiling << " to graph 1, first " << ceiling
        << " nohead dt 2 lc rgb '#b00000'\n";
    // Log axis over often less than a decade: label 1-2-5 steps, not only decades.
    g << "set xtics (";
    bool first_tic = true;
    for (double dec = std::pow(10.0, std::floor(std::log10(wmin / 1.6))); dec <= wmax * 1.6; dec *= 10.0)
      for (double m : {1.0, 2.0, 5.0})
        if (m * dec >= wmin / 1.6 && m * dec <= wmax * 1.6) {
          g << (first_tic ? "" : ", ") << "'" << fmt(m * dec) << "' " << m * dec;
          first_tic = false;
        }
    g << ")\n";
    const char* colours[] = {"#1f77b4", "#d62728", "#9467bd"};
    const int pts[] = {7, 5, 9};
    g << "plot ";
    for (std::size_t m = 0; m < s.metrics.size(); ++m) {
      const double off = s.metrics.size() > 1 ? (m == 0 ? 0.97 : 1.03) : 1.0;  // keep the bars apart
      g << (m ? ", " : "") << dq << " index 0 using ($1*" << off << "):" << 2 + 2 * m << ":" << 3 + 2 * m
        << " with yerrorbars pt " << pts[m % 3] << " ps 1.4 lc rgb '" << colours[m % 3] << "' title "
        << gnuplot_quoted("error in " + short_metric(s.metrics[m]));
    }
    g << ", " << dq << " index 0 using 1:2:" << label_col << " with labels offset 0,1.3 font ',9' notitle"
      << ", " << dq << " index 1 using 1:2 with linespoints dt 2 lw 2 pt 6 ps 2.2 lc rgb '#555555' title "
      << "'Pareto front (particle-steps, max error + sd)'"
      << ", " << dq << " index 3 using 1:2 with points pt 12 ps 3.5 lw 2 lc rgb '#2ca02c' title 'recommended'"
      << ", " << dq << " index 2 using 1:2 with points pt 2 ps 2.5 lw 2 lc rgb '#b00000' title 'failed (drawn at the top)'"
      << ", " << dq << " index 2 using 1:2:3 with labels offset 0,-1.3 font ',9' tc rgb '#b00000' notitle\n";
  }
  run_gnuplot_script(script.string());
  image.commit();
  k.chart = png.string();
}

void write_fidelity_csv(const FidelityStudy& s, const fs::path& csv) {
  std::ofstream c(csv);
  c.precision(6);
  c << "knob,setting,baseline,reference,replicas,failed,wall_s,particle_steps";
  for (const auto& m : s.metrics) c << "," << m << "_mean," << m << "_sd," << m << "_error";
  c << ",score,pass,pareto,recommended,failures\n";
  for (const auto& k : s.knobs)
    for (const auto& p : k.points) {
      c << k.name << "," << p.label << "," << p.baseline << "," << p.reference << "," << p.replicas << "," << p.failed
        << "," << p.wall_s << "," << p.work;
      for (std::size_t m = 0; m < s.metrics.size(); ++m) c << "," << p.mean[m] << "," << p.sd[m] << "," << p.error[m];
      std::string fails;
      for (const auto& e : p.failures) fails += (fails.empty() ? "" : "; ") + e;
      std::replace(fails.begin(), fails.end(), '"', '\'');
      c << "," << p.score << "," << p.pass << "," << p.pareto << "," << p.recommended << ",\"" << fails << "\"\n";
    }
  close_checked(c, csv.string());
}

}  // namespace

std::vector<std::string> fidelity_knob_names(const std::string& name) {
  std::vector<std::string> out;
  for (const auto& k : fidelity_def(name, false).knobs) out.push_back(k.name);
  return out;
}

// The jobs of each selected knob, parsed (validated). A grid path such as
// grid.dt_factor[3] is the study's, not the user's: an error names the knob, and
// --reference when the user chose that value.
std::vector<std::vector<Job>> knob_job_sets(const FidelityDef& d, const std::vector<KnobDef>& knobs,
                                            const StudyOptions& o, const std::string& name, int replicas) {
  std::vector<std::vector<Job>> jobs;
  for (const auto& k : knobs) {
    std::vector<Job> kj;
    for (const auto& j : knob_jobs(d, k, o.quick, replicas)) {
      try {
        kj.push_back(parse_job(j.dump(2), "study " + name));
      } catch (const JobError& e) {
        const bool given = std::any_of(o.reference.begin(), o.reference.end(), [&](const auto& r) {
          return find_knob(d, r.first) == find_knob(d, k.name);
        });
        throw JobError(given ? "--reference" : "study " + name,
                       k.name + (given ? " = " + label_of(k.reference) : std::string()) + ": " + e.reason() +
                           " (in the study's job: " + e.path() + ")");
      }
    }
    jobs.push_back(std::move(kj));
  }
  return jobs;
}

void check_fidelity_options(const std::string& name, const StudyOptions& o) {
  const FidelityDef d = fidelity_def(name, o.quick);
  knob_job_sets(d, selected_knobs(d, o), o, name, effective_replicas(o));
}

FidelityStudy run_fidelity_study(db::Store& store, const std::string& name, const StudyOptions& o) {
  const FidelityDef d = fidelity_def(name, o.quick);
  const std::vector<KnobDef> knobs = selected_knobs(d, o);
  FidelityStudy s;
  s.name = name;
  s.scene = d.scene;
  s.metrics = d.metrics;
  s.tolerance = o.tolerance > 0 ? o.tolerance : 2.0;
  s.replicas = effective_replicas(o);
  for (const auto& k : d.knobs) {
    s.baseline += (s.baseline.empty() ? "" : ", ") + k.name + " " + label_of(d.base.at(k.params.front()).get<double>());
  }

  // Every job is validated before any runs: an invalid one writes nothing.
  const std::vector<std::vector<Job>> jobs = knob_job_sets(d, knobs, o, name, s.replicas);
  const fs::path dir = o.out_dir;
  fs::create_directories(dir / "jobs");
  std::set<std::string> keys;
  for (const auto& kj : jobs)
    for (const auto& j : kj) {
      const fs::path f = dir / "jobs" / (j.name + ".json");
      std::ofstream jf(f);
      jf << j.spec.dump(2) << "\n";
      close_checked(jf, f.string());
      s.job_files.push_back(f.string());
      for (const auto& t : j.tasks) keys.insert(t.key);
    }
  s.tasks = static_cast<int>(keys.size());

  RunOptions ro;
  ro.workers = o.workers;
  ro.out_dir = (dir / "tasks").string();
  ro.terminal = o.terminal;
  ro.log = o.log;
  for (const auto& kj : jobs)
    for (const auto& j : kj) {
      const RunSummary sum = run_job(store, j, ro);
      if (sum.interrupted) throw std::runtime_error("study interrupted: finished tasks are kept, run it again to resume");
      if (sum.unfinished > 0) throw std::runtime_error("study: " + std::to_string(sum.unfinished) + " tasks of job " + j.name + " unfinished");
      s.ran += sum.ran;
    }

  s.reused = s.tasks - s.ran;
  const std::size_t nm = d.metrics.size();
  for (std::size_t ki = 0; ki < knobs.size(); ++ki) {
    const KnobDef& kd = knobs[ki];
    FidelityKnob k;
    k.name = kd.name;
    k.what = kd.what;
    for (const auto& p : kd.params) k.param += (k.param.empty() ? "" : ",") + p;
    std::vector<ResultRow> rows;
    for (const auto& j : jobs[ki]) {
      k.jobs.push_back(j.name);
      for (auto& r : select_rows(store, j.name, {})) rows.push_back(std::move(r));
    }
    const double base_value = d.base.at(kd.params.front()).get<double>();
    for (const auto& v : kd.values) {
      FidelityPoint p;
      p.value = v.get<double>();
      p.label = label_of(p.value);
      p.baseline = same_value(p.value, base_value);
      p.reference = same_value(p.value, kd.reference);
      std::vector<std::vector<double>> vals(nm);
      std::vector<double> ok_wall, failed_wall, ok_work;
      for (const auto& r : rows) {
        if (!same_value(r.params.at(kd.params.front()).get<double>(), p.value)) continue;
        ++p.replicas;
        const double wall = std::isfinite(metric(r, "wall_s")) ? metric(r, "wall_s") : r.task.wall_s;
        std::string why;
        if (r.task.status != "done") {
          why = r.task.error.empty() ? r.task.status : r.task.error;
        } else {
          for (const auto& m : d.metrics)
            if (!std::isfinite(metric(r, m))) why += (why.empty() ? "done but no " : ", ") + m;
        }
        const std::string seed = "seed " + r.params.at("seed").dump();
        if (!why.empty()) {
          ++p.failed;
          p.failures.push_back(seed + ": " + why.substr(0, 240));
          s.failures.push_back(k.name + "=" + p.label + " " + seed + ": " + why.substr(0, 240));
          if (std::isfinite(wall)) failed_wall.push_back(wall);
          continue;
        }
        ok_wall.push_back(wall);
        ok_work.push_back(metric(r, "particles") * metric(r, "steps"));
        for (std::size_t m = 0; m < nm; ++m) vals[m].push_back(metric(r, d.metrics[m]));
      }
      const auto mean_of = [](const std::vector<double>& x) {
        double t = 0;
        for (double e : x) t += e;
        return x.empty() ? NAN : t / static_cast<double>(x.size());
      };
      p.wall_s = ok_wall.empty() ? mean_of(failed_wall) : mean_of(ok_wall);
      p.work = mean_of(ok_work);
      p.mean.assign(nm, NAN);
      p.sd.assign(nm, NAN);
      p.error.assign(nm, NAN);
      for (std::size_t m = 0; m < nm; ++m) {
        if (vals[m].empty()) continue;
        p.mean[m] = mean_of(vals[m]);
        double ss = 0;
        for (double e : vals[m]) ss += (e - p.mean[m]) * (e - p.mean[m]);
        p.sd[m] = vals[m].size() > 1 ? std::sqrt(ss / static_cast<double>(vals[m].size() - 1)) : 0.0;
      }
      k.points.push_back(p);
    }
    const auto ref = std::find_if(k.points.begin(), k.points.end(), [](const FidelityPoint& p) { return p.reference; });
    const bool have_ref = ref != k.points.end() && std::isfinite(ref->mean[0]);
    if (have_ref) {
      for (auto& p : k.points) {
        double score = 0;
        for (std::size_t m = 0; m < nm; ++m) {
          p.error[m] = std::abs(p.mean[m] - ref->mean[m]);
          score = std::max(score, p.error[m] + p.sd[m]);
        }
        p.score = std::isfinite(p.mean[0]) ? score : NAN;
        p.pass = p.failed == 0 && std::isfinite(p.score) && p.score <= s.tolerance;
      }
    }
    mark_fidelity_pareto(k.points);
    FidelityPoint* best = nullptr;
    for (auto& p : k.points)
      if (p.pass && (!best || p.work < best->work)) best = &p;
    std::ostringstream rec;
    rec << k.name << ": ";
    const std::string ref_label = ref != k.points.end() ? ref->label : label_of(kd.reference);
    if (!have_ref) {
      rec << "no recommendation: the reference " << ref_label << " failed in every replica";
    } else if (!best) {
      rec << "no setting within " << fmt(s.tolerance) << " deg of the reference " << ref_label
          << " (error + replica sd, every replica ok)";
    } else {
      best->recommended = true;
      k.recommended = best->value;
      rec << "recommended " << best->label << " (";
      for (std::size_t m = 0; m < nm; ++m)
        rec << (m ? ", " : "") << short_metric(d.metrics[m]) << " error " << fmt(best->error[m], 2) << " +/- "
            << fmt(best->sd[m], 2) << " deg";
      rec << "; " << std::llround(best->work / 1e6) << " million particle-steps, " << fmt(best->wall_s, 4)
          << " s, against " << std::llround(ref->work / 1e6) << " million and " << fmt(ref->wall_s, 4)
          << " s for the reference " << ref_label
          << "): the cheapest setting (fewest particle-steps) within " << fmt(s.tolerance)
          << " deg including the replica spread";
    }
    k.recommendation = rec.str();
    s.knobs.push_back(std::move(k));
  }

  std::ostringstream summary;
  summary << "recommended settings (" << s.name << ", one knob at a time around the baseline, tolerance "
          << fmt(s.tolerance) << " deg):";
  bool any = false;
  for (const auto& k : s.knobs) {
    summary << (any ? ", " : " ") << k.name << " " << (std::isfinite(k.recommended) ? label_of(k.recommended) : "none");
    any = true;
  }
  s.recommendation = summary.str();

  for (auto& k : s.knobs) {
    write_fidelity_chart(s, k, dir);
    s.files.push_back(k.chart);
  }
  // A run of some knobs names its table after them, so that runs of other knobs
  // into the same folder keep theirs (the charts are per knob already).
  std::string stem = s.name;
  if (knobs.size() < d.knobs.size())
    for (const auto& k : knobs) stem += "-" + k.name;
  const fs::path csv = dir / (stem + ".csv");
  write_fidelity_csv(s, csv);
  s.files.push_back(csv.string());
  const fs::path rec = dir / (stem + "_recommendation.txt");
  {
    std::ofstream r(rec);
    for (const auto& k : s.knobs) r << k.recommendation << "\n";
    r << s.recommendation << "\n";
    if (!s.failures.empty()) {
      r << "failed tasks:\n";
      for (const auto& f : s.failures) r << "  " << f << "\n";
    }
    close_checked(r, rec.string());
  }
  s.files.push_back(rec.string());
  return s;
}

}  // namespace demcal::jobs
