// Triaxial validation against the seed's Table 2.2 (theta = 30 deg, eta = 0.1, dense,
// p0 = 100 kPa: phi_peak 41.4 deg, phi_cv 32.6 deg).
//
//   bench_triaxial_validation [key=value ...]
//     particles=2000 packing=dense|loose theta=30 eta=0.1 b=1 p0=100e3 rate=1e-4
//     strain=0.30 dt_factor=0.3 fdt=0 damping=0.3 shear_damping=0 ufr=0.01 stol=0.01 phi0=0.30 seed=1
//     twist=0 threads=1 budget=400000 alpha=0.5 beta=0.02 csv=triaxial_series.csv quiet=0
// Prints the stages, the metrics and the wall time; writes the series as CSV.
#include "engine/scenes/triaxial.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <stdexcept>
#include <string>

using namespace demcal::engine;

namespace {
struct Printer : Observer {
  bool quiet = false;
  std::chrono::steady_clock::time_point t0 = std::chrono::steady_clock::now();
  double secs() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  void on_stage(const std::string& s) override {
    std::printf("[%8.1f s] stage %s\n", secs(), s.c_str());
    std::fflush(stdout);
  }
  void on_series_row(const std::string&, const std::vector<std::string>& cols, const std::vector<double>& r) override {
    if (quiet) return;
    auto v = [&](const char* name) {
      for (std::size_t i = 0; i < cols.size(); ++i)
        if (cols[i] == name) return r[i];
      return 0.0;
    };
    static int n = 0;
    if (n++ % 10 == 0)
      std::printf("[%8.1f s] eps1 %.3f eps_v %+.4f n %.4f n_in %.4f s1 %.0f s2 %.0f s3 %.0f p %.0f phi %.2f "
                  "lw_p %.0f Z %.2f ufr %.3g I %.2e\n",
                  secs(), v("eps1"), v("eps_v"), v("porosity"), v("porosity_interior"), v("sigma1"), v("sigma2"),
                  v("sigma3"), v("p"), v("phi_mob_deg"), v("lw_p"), v("z_all"), v("ufr"), v("inertial"));
    std::fflush(stdout);
  }
};
}  // namespace

const char* const kUsage =
    "usage: bench_triaxial_validation [key=value ...]\n"
    "  particles=2000 packing=dense|loose theta=30 eta=0.1 b=1 twist=0 p0=100e3 rate=1e-4 strain=0.30\n"
    "  ramp lat_rate dt_factor=0.3 fdt=0 damping=0.3 shear_damping=0 pfactor unload ufr=0.01 stol=0.01 phi0=0.30\n"
    "  prep_rate budget=400000 alpha=0.5 beta=0.02 seed=1 threads=1 csv=triaxial_series.csv quiet=0\n";

int main(int argc, char** argv) {
  std::map<std::string, std::string> kv;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "-h" || a == "--help" || a == "help") {
      std::printf("%s", kUsage);
      return 0;
    }
    const auto eq = a.find('=');
    if (eq == std::string::npos) {
      std::fprintf(stderr, "argument %s is not key=value\n%s", a.c_str(), kUsage);
      return 2;
    }
    kv[a.substr(0, eq)] = a.substr(eq + 1);
  }
  // Every key the driver reads is recorded: a key given but never read (a misspelt
  // one) is refused below, before the run, instead of running the defaults (minutes).
  std::set<std::string> read;
  std::string bad;
  auto num = [&](const char* k, double def) {
    read.insert(k);
    if (!kv.count(k)) return def;
    char* end = nullptr;
    const double v = std::strtod(kv[k].c_str(), &end);
    if (kv[k].empty() || *end != '\0') bad = std::string(k) + "=" + kv[k] + ": expected a number";
    return v;
  };
  auto text = [&](const char* k, const char* def) {
    read.insert(k);
    return kv.count(k) ? kv[k] : std::string(def);
  };
  const std::string packing = text("packing", "dense");
  if (packing != "dense" && packing != "loose") bad = "packing=" + packing + ": expected dense or loose";
  TriaxialConfig c;
  c.particles = static_cast<std::size_t>(num("particles", 2000));
  c.packing = packing == "loose" ? Packing::loose : Packing::dense;
  c.material.friction_angle = deg_to_rad(num("theta", 30.0));
  c.material.rolling_eta = num("eta", 0.1);
  c.material.rolling_twist = num("twist", 0) != 0;
  c.material.rolling_b = num("b", 1.0);
  c.confining_pressure = num("p0", 100e3);
  c.strain_rate = num("rate", 1e-4);
  c.axial_strain = num("strain", 0.30);
  c.shear_ramp_strain = num("ramp", c.shear_ramp_strain);
  c.shear_servo_strain_rate = num("lat_rate", c.shear_servo_strain_rate);
  c.cv_to = std::min(c.cv_to, c.axial_strain);
  if (c.axial_strain < 0.3) c.cv_from = c.axial_strain * 2.0 / 3.0;
  c.dt_factor = num("dt_factor", c.dt_factor);
  c.frictionless_dt_scale = num("fdt", c.frictionless_dt_scale);
  c.prep_damping = num("damping", c.prep_damping);
  c.shear_damping = num("shear_damping", c.shear_damping);
  c.prep_pressure_factor = num("pfactor", c.prep_pressure_factor);
  c.unloading_steps = static_cast<long>(num("unload", static_cast<double>(c.unloading_steps)));
  c.ufr_tolerance = num("ufr", c.ufr_tolerance);
  c.stress_tolerance = num("stol", c.stress_tolerance);
  c.initial_solid_fraction = num("phi0", c.initial_solid_fraction);
  c.prep_strain_rate = num("prep_rate", c.prep_strain_rate);
  c.prep_step_budget = static_cast<long>(num("budget", static_cast<double>(c.prep_step_budget)));
  c.servo_alpha = num("alpha", c.servo_alpha);
  c.servo_beta = num("beta", c.servo_beta);
  c.seed = static_cast<std::uint64_t>(num("seed", 1));
  c.threads = static_cast<int>(num("threads", 1));
  const std::string csv = text("csv", "triaxial_series.csv");
  const bool quiet = num("quiet", 0) != 0;
  for (const auto& entry : kv)
    if (!read.count(entry.first)) {
      std::fprintf(stderr, "unknown key %s\n%s", entry.first.c_str(), kUsage);
      return 2;
    }
  if (!bad.empty()) {
    std::fprintf(stderr, "%s\n", bad.c_str());
    return 2;
  }

  Printer obs;
  obs.quiet = quiet;
  TriaxialResult r;
  try {
    r = run_triaxial(c, &obs);
  } catch (const std::invalid_argument& e) {  // a bad argument (field named), not std::terminate
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  }
  std::printf("status %s%s%s\n", to_string(r.outcome.status),
              r.outcome.failed_stage.empty() ? "" : (" in " + r.outcome.failed_stage).c_str(),
              r.outcome.message.empty() ? "" : (": " + r.outcome.message).c_str());
  std::printf("dt %.4g s (critical %.4g s, %s), grain density %.3g kg/m3, d_mean %.4g m\n", r.dt, r.dt_critical,
              r.critical_mode.c_str(), r.grain_density, r.d_mean);
  for (const auto& s : r.stages)
    std::printf("stage %-22s converged %d steps %8ld stress_err %.4f ufr %.4g porosity %.4f p %.0f Pa\n",
                s.name.c_str(), s.converged ? 1 : 0, s.steps, s.stress_error, s.ufr, s.porosity, s.mean_stress);
  for (const auto& m : r.metrics()) std::printf("  %-28s %.6g\n", m.first.c_str(), m.second);
  std::printf("sample %.4g x %.4g x %.4g m, %s\n", r.sample_size[0], r.sample_size[1], r.sample_size[2],
              r.walls.c_str());
  std::printf("wall time %.1f s on %d thread(s), %ld steps\n", r.wall_seconds, r.threads, r.steps);
  std::ofstream out(csv);
  for (std::size_t i = 0; i < r.series.columns.size(); ++i) out << (i ? "," : "") << r.series.columns[i];
  out << "\n";
  out.precision(8);
  for (const auto& row : r.series.rows) {
    for (std::size_t i = 0; i < row.size(); ++i) out << (i ? "," : "") << row[i];
    out << "\n";
  }
  return r.outcome.ok() ? 0 : 1;
}
