#include "common.hpp"

#include "jobs/job_spec.hpp"
#include "jobs/scene_registry.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <sstream>

namespace demcal::cli {
namespace {

// One core's speed on the triaxial scene, measured on the 2-core machine
// docs/performance.md describes (2026-11-27, physics version 3; whole runs, wall time
// over steps and grains): 62 ns per grain-step at 500 grains, 73 at 2,000, 99 at
// 10,000 (larger samples leave the caches). A yardstick for the forecast, not a
// promise for another machine.
double ns_per_grain_step(double grains) {
  const double x[] = {std::log10(500.0), std::log10(2000.0), std::log10(10000.0)}, y[] = {62.0, 73.0, 99.0};
  const double g = std::clamp(std::log10(std::max(grains, 1.0)), x[0], x[2]);
  const int k = g <= x[1] ? 0 : 1;
  return y[k] + (y[k + 1] - y[k]) * (g - x[k]) / (x[k + 1] - x[k]);
}

std::string sig2(double v) {
  std::ostringstream os;
  os << std::setprecision(2) << v;
  return os.str();
}

// What the job will cost, from the part of each task's work known before it runs.
void print_work(const jobs::Job& job) {
  const jobs::SceneDef* scene = jobs::find_scene(job.scene);
  if (!scene || !scene->work) return;
  double lo = INFINITY, hi = 0, total = 0, seconds = 0;
  for (const auto& t : job.tasks) {
    const jobs::Work w = scene->work(t.params);
    const double gs = w.steps * w.grains;
    lo = std::min(lo, gs), hi = std::max(hi, gs), total += gs;
    seconds += gs * ns_per_grain_step(w.grains) * 1e-9;
  }
  const double minutes = seconds / 60.0;
  std::cout << "work: " << scene->work_of << " is " << sig2(lo) << (hi > lo * 1.005 ? " to " + sig2(hi) : std::string())
            << " grain-steps a task, " << sig2(total) << " in all: about "
            << (minutes < 1.0 ? "1 core-minute or less" : sig2(minutes) + " core-minutes")
            << " at the speed of one core of the machine docs/performance.md measures (divide by --workers"
            << (job.scene == "triaxial" ? "; the preparation adds 5-15%" : "") << ")\n";
}

}  // namespace

void add_validate(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("validate", "Check a job file; print its task count and first task's parameters");
  auto file = std::make_shared<std::string>();
  cmd->add_option("JOB", *file, "job file (JSON)")->required()->check(kPlainPath);
  cmd->callback([file, &exit_code] {
    exit_code = guarded(*file, [&] {
      const jobs::Job job = jobs::load_job_file(*file);
      std::string axes;
      for (const auto& a : job.axes) axes += (axes.empty() ? "" : " x ") + a;
      std::cout << "job " << job.name << ": scene " << job.scene << ", fidelity " << job.fidelity << "\n"
                << job.tasks.size() << " task(s)"
                << (axes.empty() ? std::string() : " over " + axes) << ", " << job.replicas << " replica(s)\n"
                << "first task (key " << job.tasks.front().key << "):\n"
                << job.tasks.front().params.dump(2) << "\n";
      print_work(job);
      print_notes(*file, job.notes);
      return kOk;
    });
  });
}

}  // namespace demcal::cli
