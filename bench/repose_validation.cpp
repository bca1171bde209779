// Validation of the repose scene against the seed's Fig. 2.15 (theta = 30 deg,
// eta = 0.1: 31.3 deg). Runs one column collapse, prints the metrics and the wall
// time, and writes the final grains and profile as CSV for docs/plots/.
//
//   bench_repose_validation [--seed N] [--threads N] [--scale S] [--theta DEG]
//       [--eta E] [--width M] [--height M] [--depth D] [--time-limit S]
//       [--dt-factor K] [--side-walls periodic|smooth|frictional] [--out PREFIX]
#include "engine/scenes/repose.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>

using namespace demcal::engine;

namespace {
class Progress : public Observer {
 public:
  void on_stage(const std::string& s) override {
    std::fprintf(stderr, "[stage] %s at %.1f s\n", s.c_str(), secs());
  }
  void on_series_row(const std::string&, const std::vector<std::string>&, const std::vector<double>& row) override {
    if (++n_ % 20 == 0)
      std::fprintf(stderr, "  t=%.3f s  ke/grain=%.3e J  flow=%.3e J  front=%.4f m  (wall %.1f s)\n", row[0], row[2],
                   row[3], row[4], secs());
  }

 private:
  double secs() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count(); }
  std::chrono::steady_clock::time_point t0_ = std::chrono::steady_clock::now();
  long n_ = 0;
};
}  // namespace

const char* const kUsage =
    "usage: bench_repose_validation [--seed N] [--threads N] [--scale S] [--theta DEG] [--eta E]\n"
    "  [--width M] [--height M] [--depth D] [--time-limit S] [--dt-factor K] [--length M] [--rest R]\n"
    "  [--drag D] [--prep-damping A] [--side-walls periodic|smooth|frictional] [--out PREFIX]\n";

int main(int argc, char** argv) {
  ReposeConfig c;
  std::string out;
  for (int i = 1; i < argc; ++i)
    if (!std::strcmp(argv[i], "-h") || !std::strcmp(argv[i], "--help")) {
      std::printf("%s", kUsage);
      return 0;
    }
  if (argc % 2 == 0) {  // options come in pairs: a lone one would be dropped and the defaults run (minutes)
    std::fprintf(stderr, "option %s has no value\n%s", argv[argc - 1], kUsage);
    return 2;
  }
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    char* end = nullptr;
    const double v = std::strtod(argv[i + 1], &end);
    if (k != "--side-walls" && k != "--out" && (*argv[i + 1] == '\0' || *end != '\0')) {
      std::fprintf(stderr, "%s %s: expected a number\n", k.c_str(), argv[i + 1]);
      return 2;
    }
    if (k == "--side-walls") {
      if (!parse_side_walls(argv[i + 1], c.side_walls)) {
        std::fprintf(stderr, "--side-walls: expected periodic, smooth or frictional, got %s\n", argv[i + 1]);
        return 2;
      }
      continue;
    }
    if (k == "--seed") c.seed = static_cast<std::uint64_t>(v);
    else if (k == "--threads") c.threads = static_cast<int>(v);
    else if (k == "--scale") c.stiffness_scale = v;
    else if (k == "--theta") c.material.friction_angle = deg_to_rad(v);
    else if (k == "--eta") c.material.rolling_eta = v;
    else if (k == "--width") c.column_width = v;
    else if (k == "--height") c.column_height = v;
    else if (k == "--depth") c.slab_depth_diameters = v;
    else if (k == "--time-limit") c.time_limit = v;
    else if (k == "--dt-factor") c.dt_factor = v;
    else if (k == "--length") c.domain_length = v;
    else if (k == "--rest") c.rest_ke_ratio = v;
    else if (k == "--drag") c.collapse_drag = v;
    else if (k == "--prep-damping") c.prep_damping = v;
    else if (k == "--out") out = argv[i + 1];
    else {
      std::fprintf(stderr, "unknown option %s\n%s", k.c_str(), kUsage);
      return 2;
    }
  }
  Progress prog;
  ReposeResult r;
  try {
    r = run_repose(c, &prog);
  } catch (const std::invalid_argument& e) {  // a bad argument (field named), not std::terminate
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  }
  std::printf("status %s%s%s\n", to_string(r.outcome.status), r.outcome.failed_stage.empty() ? "" : " in ",
              r.outcome.failed_stage.c_str());
  if (!r.outcome.message.empty()) std::printf("message %s\n", r.outcome.message.c_str());
  std::printf("boundaries %s\n", r.boundaries.c_str());
  std::printf("critical_mode %s\n", r.critical_mode.c_str());
  std::printf("theta_deg %.2f eta %.3f seed %llu\n", rad_to_deg(c.material.friction_angle), c.material.rolling_eta,
              static_cast<unsigned long long>(c.seed));
  for (const auto& [k, v] : r.metrics()) std::printf("%s %.6g\n", k.c_str(), v);
  if (!out.empty()) {
    if (FILE* f = std::fopen((out + "_grains.csv").c_str(), "w")) {
      std::fprintf(f, "x,y,z,r,fixed\n");
      const Particles& p = r.final_particles;
      for (std::size_t i = 0; i < p.size(); ++i)
        std::fprintf(f, "%.6e,%.6e,%.6e,%.6e,%d\n", p.x[i][0], p.x[i][1], p.x[i][2], p.r[i], p.fixed[i]);
      std::fclose(f);
    }
    if (FILE* f = std::fopen((out + "_profile.csv").c_str(), "w")) {
      std::fprintf(f, "x,h,count\n");
      for (const auto& row : r.profile.rows) std::fprintf(f, "%.6e,%.6e,%d\n", row[0], row[1], static_cast<int>(row[2]));
      std::fclose(f);
    }
    if (FILE* f = std::fopen((out + "_energy.csv").c_str(), "w")) {
      std::fprintf(f, "time,kinetic,ke_per_grain,ke_flow_per_grain,front_x,repose_deg\n");
      for (const auto& row : r.energy.rows)
        std::fprintf(f, "%.6e,%.6e,%.6e,%.6e,%.6e,%.6e\n", row[0], row[1], row[2], row[3], row[4], row[5]);
      std::fclose(f);
    }
    if (FILE* f = std::fopen((out + "_prep.csv").c_str(), "w")) {
      std::fprintf(f, "time,ke_per_grain,ke_flow_per_grain\n");
      for (const auto& row : r.prep.rows) std::fprintf(f, "%.6e,%.6e,%.6e\n", row[0], row[1], row[2]);
      std::fclose(f);
    }
    if (FILE* f = std::fopen((out + "_fit.txt").c_str(), "w")) {
      // gnuplot-readable: floor level, fit line h = a + b x over [x_upper, x_lower]
      std::fprintf(f, "floor_level=%.6e\nfit_a=%.6e\nfit_b=%.6e\nfit_x1=%.6e\nfit_x2=%.6e\nrepose=%.3f\nfit_err=%.3f\n"
                   "steepest=%.3f\nfront=%.6e\nrepose_upper=%.3f\nrepose_lower=%.3f\n",
                   r.floor_level, r.fit_intercept, r.fit_slope, r.fit_x_upper, r.fit_x_lower, r.repose_deg,
                   r.repose_fit_err_deg, r.steepest_deg, r.front_m, r.repose_upper_deg, r.repose_lower_deg);
      std::fclose(f);
    }
  }
  return r.outcome.ok() ? 0 : 1;
}
