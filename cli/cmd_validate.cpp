#include "common.hpp"

#include "jobs/job_spec.hpp"
#include "jobs/scene_registry.hpp"
#include "jobs/work_forecast.hpp"

#include <iostream>
#include <vector>

namespace demcal::cli {
namespace {

void print_work(const jobs::Job& job) {
  const jobs::SceneDef* scene = jobs::find_scene(job.scene);
  if (!scene) return;
  std::vector<nlohmann::json> params;
  for (const auto& t : job.tasks) params.push_back(t.params);
  const jobs::WorkForecast w = jobs::forecast_work(*scene, params);
  if (w.known) std::cout << "work: " << jobs::describe(w) << "\n";
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
