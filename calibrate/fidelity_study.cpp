// The fidelity studies (triaxial and repose): one knob at a time around a baseline (issue 9).
#include "excerpt.hpp"
#include "metric.hpp"
#include "db/store.hpp"
#include "study.hpp"
#include "study_support.hpp"
#include "engine/scenes/triaxial.hpp"

#include <algorithm>
#include <map>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <set>
#include <sstream>

namespace demcal::calibrate {
namespace fs = std::filesystem;
using namespace study_support;
namespace {
struct KnobDef {
  std::string name;
  std::vector<std::string> aliases;   // also accepted by --knobs / --reference
  std::vector<std::string> params;    // each setting sets all of these to its value
  std::string what;                   // axis words
  std::vector<nlohmann::json> values; // settings (the baseline's value among them)
  double reference = 0;               // the most expensive setting
  std::string section = "";           // the job section of params: the scene's when empty
  // Further settings that follow the knob's value, written into each setting's job
  // (one job a setting then: a grid would cross them).
  std::function<void(nlohmann::json& job, double value)> follow = nullptr;
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

bool same_value(double a, double b) { return std::abs(a - b) <= 1e-9 * std::max(std::abs(a), std::abs(b)); }

double three_digits(double v) { return std::stod(fmt(v, 3)); }

// A triaxial job's grains made softer or stiffer than its material's: kn set, and
// what must follow it so that the preparation does what it does at the material's
// stiffness. ks keeps its ratio to kn. The preparation's walls move sqrt(kn / kn0) as
// fast, which presses a grain as deep into a wall on impact (speed x sqrt(m / kn);
// at the seed's rate 500 grains of kn = 1.1e4 N/m blow up within 100 steps) and takes
// as many steps. The dense preparation's extra load comes down so that kn / (p d_min)
// stays at least 3,000 there, as for the seed's material at 100 p0.
void follow_stiffness(nlohmann::json& j, double kn) {
  const nlohmann::json& m = j.at("material");
  const double kn0 = m.at("kn").get<double>();
  if (same_value(kn, kn0)) return;
  const engine::TriaxialConfig defaults;
  nlohmann::json& t = j.at("triaxial");
  j["material"]["ks"] = three_digits(m.at("ks").get<double>() * kn / kn0);
  const double rate = t.value("prep_strain_rate", defaults.prep_strain_rate);
  t["prep_strain_rate"] = three_digits(rate * std::sqrt(kn / kn0));
  const double kappa = kn / (t.at("confining_kpa").get<double>() * 1e3 * m.at("diameter").at("min").get<double>());
  const double factor = t.value("prep_pressure_factor", defaults.prep_pressure_factor);
  t["prep_pressure_factor"] = three_digits(std::clamp(kappa / 3000.0, 1.0, std::max(factor, 1.0)));
}

// The grains' stiffness, the seed's kn the most expensive setting (the step grows as
// 1 / sqrt(kn)).
KnobDef stiffness_knob(std::vector<nlohmann::json> kns) {
  KnobDef k{"stiffness", {"kn"}, {"kn"}, "normal stiffness kn [N/m] (ks and the preparation follow)", std::move(kns), 3e7};
  k.section = "material";
  k.follow = follow_stiffness;
  return k;
}

FidelityDef fidelity_def(const std::string& name, bool quick, bool smoothed_peak) {
  if (smoothed_peak && name != "fidelity")
    throw JobError("--peak", "study " + name + " has no peak strength to smooth: --peak applies to the (triaxial) "
                             "fidelity study only");
  FidelityDef d;
  d.name = name;
  d.material = seed_material();
  if (name == "fidelity") {
    d.scene = "triaxial";
    d.metrics = {smoothed_peak ? "phi_peak_smoothed_deg" : "phi_peak_deg", "phi_cv_deg"};
    // The baseline is the seed study's (examples/seed-study): dense, 100 kPa,
    // theta 30 deg, eta 0.1, 500 grains, 3e-4 /s, so its tasks are shared with it.
    if (!quick) {
      d.base = {{"packing", "dense"}, {"confining_kpa", 100.0}, {"axial_strain", 0.3}, {"particles", 500},
                {"strain_rate", 3e-4}, {"dt_factor", 0.3}, {"scaled_density", 2.65e12}};
      d.knobs = {{"particles", {}, {"particles"}, "particle count", {250, 500, 1000, 2000}, 2000},
                 {"rate", {"strain_rate"}, {"strain_rate"}, "axial strain rate [1/s]", {1e-4, 3e-4, 1e-3}, 1e-4},
                 {"dt", {"dt_factor"}, {"dt_factor"}, "dt factor", {0.15, 0.3, 0.45}, 0.15},
                 {"density", {"scaled_density", "density_scale"}, {"scaled_density"}, "scaled grain density [kg/m^3]",
                  {2.65e11, 2.65e12, 2.65e13}, 2.65e11},
                 stiffness_knob({3e4, 3e5, 3e6, 3e7})};
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
                  {2.65e12, 2.65e13}, 2.65e12},
                 stiffness_knob({3e6, 3e7})};
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

double baseline_value(const FidelityDef& d, const KnobDef& k) {
  return (k.section == "material" ? d.material : d.base).at(k.params.front()).get<double>();
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
  const std::string section = k.section.empty() ? d.scene : k.section;
  if (k.params.size() == 1 && !k.follow) {
    nlohmann::json j = base_job(d, prefix, replicas, k.what);
    j[section].erase(k.params.front());
    j["grid"] = {{k.params.front(), k.values}};
    jobs.push_back(j);
  } else {
    for (const auto& v : k.values) {
      const std::string label = label_of(v.get<double>());
      std::string in_name = label;  // a job name holds no '+' (3e+04)
      in_name.erase(std::remove(in_name.begin(), in_name.end(), '+'), in_name.end());
      nlohmann::json j = base_job(d, prefix + "-" + in_name, replicas, k.what + " = " + label);
      if (k.follow) k.follow(j, v.get<double>());
      for (const auto& p : k.params) j[section][p] = v;
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
  if (m == "phi_peak_smoothed_deg") return "phi_peak (running mean)";
  if (m == "phi_cv_deg") return "phi_cv";
  if (m == "repose_deg") return "repose angle";
  return m;
}

// The chart's data in four blocks: 0 settings with an error (wall, then error and sd
// per metric, label), 1 Pareto front by wall time, 2 failed settings (drawn at
// `ceiling`, at `wmin` without a wall time), 3 the recommended setting.
void write_chart_data(const FidelityStudy& s, const FidelityKnob& k, const fs::path& data, double wmin, double ceiling) {
  std::ofstream f(data);
  f.precision(8);
  const auto quoted = [](const FidelityPoint& p) {
    return "\"" + p.label + (p.reference ? " (ref)" : "") + (p.failed > 0 && p.failed < p.replicas ? " (" +
           std::to_string(p.failed) + "/" + std::to_string(p.replicas) + " failed)" : "") +
           (p.spikes.empty() ? "" : " (" + std::to_string(p.spikes.size()) + "/" + std::to_string(p.replicas) +
            " peak on a spike)") + "\"";
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

// The chart's gnuplot script: errors with replica bars against wall time (log axis,
// [wmin, wmax]), the tolerance, the Pareto front, the recommended and failed settings.
void write_chart_script(const FidelityStudy& s, const FidelityKnob& k, const fs::path& data, const fs::path& script,
                        const std::string& part, double wmin, double wmax, double ceiling) {
  const std::string dq = gnuplot_quoted(data.string());
  const int label_col = 2 + 2 * static_cast<int>(s.metrics.size());
  std::ofstream g(script);
  g << gnuplot_png_terminal(1000, 720) << "set output " << gnuplot_quoted(part) << "\n"
    << "set title " << gnuplot_quoted("demcal study " + s.name + (s.smoothed_peak ? " --peak smoothed" : "") + ": " + k.what + " against wall time (" +
                                      std::to_string(s.replicas) + (s.replicas == 1 ? " replica" : " replicas") + " per setting)") << " noenhanced\n"
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
  const std::string stem = s.stem + "_" + k.name;
  const fs::path data = dir / (stem + ".dat"), script = dir / (stem + ".gp"), png = dir / (stem + ".png");
  write_chart_data(s, k, data, wmin, ceiling);
  ImageFile image(png.string());
  write_chart_script(s, k, data, script, image.part(), wmin, wmax, ceiling);
  run_gnuplot_script(script.string());
  image.commit();
  keep_script_redrawable(script.string(), dir.string(), {{image.part(), png.string()}});
  k.chart = png.string();
}

void write_fidelity_csv(const FidelityStudy& s, const fs::path& csv) {
  WholeTextFile c(csv);
  c.precision(6);
  c << "knob,setting,baseline,reference,replicas,failed,wall_s,particle_steps";
  for (const auto& m : s.metrics) c << "," << m << "_mean," << m << "_sd," << m << "_error";
  const bool spikes = s.scene == "triaxial";  // a repose angle has no peak to spike
  c << ",score,pass,pareto,recommended" << (spikes ? ",peak_spikes" : "") << ",failures\n";
  for (const auto& k : s.knobs)
    for (const auto& p : k.points) {
      c << k.name << "," << p.label << "," << p.baseline << "," << p.reference << "," << p.replicas << "," << p.failed
        << "," << p.wall_s << "," << p.work;
      for (std::size_t m = 0; m < s.metrics.size(); ++m) c << "," << p.mean[m] << "," << p.sd[m] << "," << p.error[m];
      std::string fails;
      for (const auto& e : p.failures) fails += (fails.empty() ? "" : "; ") + e;
      std::replace(fails.begin(), fails.end(), '"', '\'');
      c << "," << p.score << "," << p.pass << "," << p.pareto << "," << p.recommended;
      if (spikes) c << "," << p.spikes.size();
      c << ",\"" << fails << "\"\n";
    }
  c.commit();
}

}  // namespace

std::vector<std::string> fidelity_knob_names(const std::string& name) {
  std::vector<std::string> out;
  for (const auto& k : fidelity_def(name, false, false).knobs) out.push_back(k.name);
  return out;
}

namespace {

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

double mean_of(const std::vector<double>& x) {
  double t = 0;
  for (double e : x) t += e;
  return x.empty() ? NAN : t / static_cast<double>(x.size());
}

// Writes every job's file (all of them valid before any runs: an invalid one writes
// nothing), then runs the jobs: s.job_files, s.tasks, s.ran and s.reused.
void run_knob_jobs(db::Store& store, const std::vector<std::vector<Job>>& jobs, const StudyOptions& o,
                   FidelityStudy& s) {
  const fs::path dir = o.out_dir;
  fs::create_directories(dir / "jobs");
  std::set<std::string> keys;
  for (const auto& kj : jobs)
    for (const auto& j : kj) {
      const fs::path f = dir / "jobs" / (j.name + ".json");
      WholeTextFile jf(f);
      jf << j.spec.dump(2) << "\n";
      jf.commit();
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
      jobs::throw_if_stopped_short(sum, "study " + j.name);
      if (sum.unfinished > 0) throw std::runtime_error("study: " + std::to_string(sum.unfinished) + " tasks of job " + j.name + " unfinished");
      s.ran += sum.ran;
    }
  s.reused = s.tasks - s.ran;
}

// One setting of knob `k` over its replicas (the rows whose first parameter is
// `value`): the metrics' mean and sd, wall time and work of the finished ones; the
// failed ones and the peaks on a spike listed in the point and in the study. The
// baseline's tasks stand in every knob's table: `counted` counts each task once in
// s.finished and s.warned.
FidelityPoint measure_setting(const FidelityDef& d, const KnobDef& kd, const std::vector<ResultRow>& rows, double value,
                              FidelityStudy& s, std::set<std::int64_t>& counted) {
  const std::size_t nm = d.metrics.size();
  FidelityPoint p;
  p.value = value;
  p.label = label_of(p.value);
  p.baseline = same_value(p.value, baseline_value(d, kd));
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
      s.failures.push_back(kd.name + "=" + p.label + " " + seed + ": " + why.substr(0, 240));
      if (std::isfinite(wall)) failed_wall.push_back(wall);
      continue;
    }
    if (counted.insert(r.task.id).second) {
      ++s.finished;
      if (const std::string w = db::task_message(r.task).warning; !w.empty()) {
        ++s.warned;
        s.not_critical += says_not_at_critical_state(w);
        s.not_quasi_static += w.find("not quasi-static") != std::string::npos;
      }
    }
    // Marked and listed: one spike can set a setting's mean, spread and verdict
    // (never for repose, whose results hold no peak).
    if (peak_on_a_spike(r.metrics)) {
      const std::string spike = seed + ": phi_peak " + fmt(metric(r, "phi_peak_deg"), 4) +
                                " deg, the running mean's peak " + fmt(metric(r, "phi_peak_smoothed_deg"), 4) + " deg";
      p.spikes.push_back(spike);
      s.spikes.push_back(kd.name + "=" + p.label + " " + spike);
    }
    ok_wall.push_back(wall);
    ok_work.push_back(metric(r, "particles") * metric(r, "steps"));
    for (std::size_t m = 0; m < nm; ++m) vals[m].push_back(metric(r, d.metrics[m]));
  }
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
  return p;
}

// Every setting's error against the reference, the Pareto front, and the knob's
// recommendation: the cheapest setting (fewest particle-steps) within the tolerance.
void judge_knob(FidelityKnob& k, const KnobDef& kd, const FidelityDef& d, const FidelityStudy& s, bool smoothed_peak) {
  const std::size_t nm = d.metrics.size();
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
  // The reference alone finished: nothing was measured against it.
  const bool alone = have_ref && std::none_of(k.points.begin(), k.points.end(), [](const FidelityPoint& p) {
    return !p.reference && std::isfinite(p.mean[0]);
  });
  k.judged = have_ref && !alone;
  if (alone) {
    rec << "no recommendation: every setting but the reference " << ref_label
        << " failed in every replica, so nothing was compared with it (the failed tasks are listed below)";
  } else if (!have_ref) {
    rec << "no recommendation: the reference " << ref_label << " failed in every replica";
  } else if (!best) {
    rec << "no setting within " << fmt(s.tolerance) << " deg of the reference " << ref_label
        << " (error + replica sd, every replica ok)";
  } else {
    best->recommended = true;
    k.recommended = best->value;
    // One replica a setting measures no spread: its sd reads 0, and the error alone
    // (one packing's) is judged. Said, not shown as "+/- 0".
    const bool spread = s.replicas > 1;
    rec << "recommended " << best->label << " (";
    for (std::size_t m = 0; m < nm; ++m)
      rec << (m ? ", " : "") << short_metric(d.metrics[m]) << " error " << fmt(best->error[m], 2)
          << (spread ? " +/- " + fmt(best->sd[m], 2) : std::string()) << " deg";
    rec << "; " << std::llround(best->work / 1e6) << " million particle-steps, " << fmt(best->wall_s, 4)
        << " s, against " << std::llround(ref->work / 1e6) << " million and " << fmt(ref->wall_s, 4)
        << " s for the reference " << ref_label
        << "): the cheapest setting (fewest particle-steps) within " << fmt(s.tolerance) << " deg"
        << (spread ? " including the replica spread"
                   : " of one replica, whose spread is not measured: more replicas (--replicas 3) may not confirm it");
  }
  std::string spiked;
  for (const auto& p : k.points)
    if (!p.spikes.empty())
      spiked += (spiked.empty() ? "" : ", ") + p.label + (p.reference ? " (the reference)" : "") + ": " +
                std::to_string(p.spikes.size()) + " of " + std::to_string(p.replicas);
  if (!spiked.empty())
    rec << "; phi_peak rests on a spike of the walls' stress in " << spiked << " replica(s), listed below"
        << (smoothed_peak ? " (judged here by the running mean's peak, " + running_mean_vs_spike() + ")"
                          : " (--peak smoothed judges the running mean's peak instead)");
  k.recommendation = rec.str();
}

// The study's one-line recommendation, and the note on warned tasks.
void summarise(FidelityStudy& s, const db::Store& store, bool smoothed_peak) {
  std::ostringstream summary;
  summary << "recommended settings (" << s.name << (smoothed_peak ? ", phi_peak by its running mean" : "")
          << ", one knob at a time around the baseline, tolerance " << fmt(s.tolerance) << " deg"
          << (s.replicas > 1 ? "" : ", one replica a setting: the spread not measured") << "):";
  bool any = false;
  for (const auto& k : s.knobs) {
    summary << (any ? ", " : " ") << k.name << " " << (std::isfinite(k.recommended) ? label_of(k.recommended) : "none");
    any = true;
  }
  s.recommendation = summary.str();
  if (s.warned == 0) return;
  std::ostringstream w;
  w << "warnings: " << s.warned << " of the " << s.finished << " finished tasks carry warnings (";
  if (s.not_critical > 0) w << s.not_critical << " not at critical state, ";
  if (s.not_quasi_static > 0) w << s.not_quasi_static << " not quasi-static, ";
  std::set<std::string> names;
  for (const auto& k : s.knobs) names.insert(k.jobs.begin(), k.jobs.end());
  std::string list;
  for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
  w << "demcal query --db " << store.path() << " --job JOB lists them, JOB one of " << list
    << "): the errors above compare "
    << "what those runs gave, and a setting judged against a warned reference inherits its warning";
  s.warnings_note = w.str();
}

// The charts, the CSV and the recommendation file, named by s.stem.
void write_study_files(FidelityStudy& s, const fs::path& dir) {
  for (auto& k : s.knobs) {
    write_fidelity_chart(s, k, dir);
    s.files.push_back(k.chart);
  }
  const fs::path csv = dir / (s.stem + ".csv");
  write_fidelity_csv(s, csv);
  s.files.push_back(csv.string());
  const fs::path rec = dir / (s.stem + "_recommendation.txt");
  WholeTextFile r(rec);
  for (const auto& k : s.knobs) r << k.recommendation << "\n";
  r << s.recommendation << "\n";
  if (!s.warnings_note.empty()) r << s.warnings_note << "\n";
  if (!s.failures.empty()) {
    r << "failed tasks:\n";
    for (const auto& f : s.failures) r << "  " << f << "\n";
  }
  if (!s.spikes.empty()) {
    r << spike_heading() << ":\n";
    for (const auto& f : s.spikes) r << "  " << f << "\n";
  }
  r.commit();
  s.files.push_back(rec.string());
}

}  // namespace

void check_fidelity_options(const std::string& name, const StudyOptions& o) {
  const FidelityDef d = fidelity_def(name, o.quick, o.smoothed_peak);
  knob_job_sets(d, selected_knobs(d, o), o, name, effective_replicas(o));
}

FidelityStudy run_fidelity_study(db::Store& store, const std::string& name, const StudyOptions& o) {
  const FidelityDef d = fidelity_def(name, o.quick, o.smoothed_peak);
  const std::vector<KnobDef> knobs = selected_knobs(d, o);
  FidelityStudy s;
  s.name = name;
  s.stem = name + (o.smoothed_peak ? "-smoothed-peak" : "");
  s.smoothed_peak = o.smoothed_peak;
  s.scene = d.scene;
  s.metrics = d.metrics;
  s.tolerance = o.tolerance > 0 ? o.tolerance : 2.0;
  s.replicas = effective_replicas(o);
  for (const auto& k : d.knobs) {
    s.baseline += (s.baseline.empty() ? "" : ", ") + k.name + " " + label_of(baseline_value(d, k));
  }
  const std::vector<std::vector<Job>> jobs = knob_job_sets(d, knobs, o, name, s.replicas);
  run_knob_jobs(store, jobs, o, s);

  std::set<std::int64_t> counted;  // tasks counted in s.finished and s.warned
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
    for (const auto& v : kd.values) k.points.push_back(measure_setting(d, kd, rows, v.get<double>(), s, counted));
    judge_knob(k, kd, d, s, o.smoothed_peak);
    s.knobs.push_back(std::move(k));
  }
  summarise(s, store, o.smoothed_peak);
  // A run of some knobs names its files after them, charts included, so that runs of
  // other knobs into the same folder keep theirs, and a chart never shows another run
  // than the table beside it.
  if (knobs.size() < d.knobs.size())
    for (const auto& k : knobs) s.stem += "-" + k.name;
  write_study_files(s, o.out_dir);
  return s;
}

bool FidelityStudy::any_judged() const {
  return std::any_of(knobs.begin(), knobs.end(), [](const FidelityKnob& k) { return k.judged; });
}

std::string spike_heading() {
  return "peak on a spike of the walls' stress (phi_peak " + spike_rule() +
         ", which phi_peak_smoothed_deg holds: the steadier figure)";
}

}  // namespace demcal::calibrate
