#include "common.hpp"

#include "db/store.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/scene_registry.hpp"
#include "jobs/work_forecast.hpp"

#include <iostream>
#include <map>
#include <set>
#include <unordered_map>
#include <vector>

namespace demcal::cli {
namespace {

// At the speed of the database's done tasks of the scene when --db names one, and of
// the tasks a run would not reuse from it.
void print_work(const jobs::Job& job, const std::string& db) {
  const jobs::SceneDef* scene = jobs::find_scene(job.scene);
  if (!scene || !scene->work) return;
  std::vector<nlohmann::json> params;
  jobs::MeasuredSpeed speed;
  int done_untimed = 0, reused = 0, failed = 0, running = 0;
  if (!db.empty()) {
    db::Store store(db, /*read_only=*/true);
    speed = jobs::measure_speed(store, *scene, job.threads > 0 ? job.threads : 1);
    std::unordered_map<std::string, std::string> status_of;
    for (const auto& t : store.tasks()) {
      status_of[t.key] = t.status;
      if (speed.tasks == 0) done_untimed += t.scene == job.scene && t.status == "done";
    }
    // What `demcal run` would not run: done tasks (reused), failed ones (left unless
    // --retry-failed), running ones (another runner's).
    for (const auto& t : job.tasks) {
      const auto it = status_of.find(t.key);
      const std::string st = it == status_of.end() ? "" : it->second;
      if (st == "done") ++reused;
      else if (st == "failed") ++failed;
      else if (st == "running") ++running;
      else params.push_back(t.params);
    }
  } else {
    for (const auto& t : job.tasks) params.push_back(t.params);
  }
  if (reused + failed + running > 0) {
    std::vector<std::string> parts;
    if (reused) parts.push_back(std::to_string(reused) + " done (demcal run reuses them)");
    if (failed) parts.push_back(std::to_string(failed) + " failed (run leaves them unless --retry-failed)");
    if (running) parts.push_back(std::to_string(running) + " running (another runner holds them)");
    std::string said;
    for (const auto& p : parts) said += (said.empty() ? "" : ", ") + p;
    std::cout << "work: of the " << job.tasks.size() << " task(s), " << db << " holds " << said << "; "
              << (params.empty() ? std::string("nothing to run") : "the other " + std::to_string(params.size()) + " below")
              << "\n";
  }
  if (params.empty()) return;
  std::cout << "work: " << jobs::describe(jobs::forecast_work(*scene, params, speed)) << "\n";
  if (!db.empty() && speed.tasks == 0)
    std::cout << "work: " << db
              << (done_untimed > 0 ? " holds " + std::to_string(done_untimed) + " done " + job.scene +
                                         " task(s), all from a demcal before tasks stored their CPU time (cpu_s)"
                                   : " holds no done " + job.scene + " task")
              << ": the forecast is at the yardstick\n";
}

// Where each of the first task's flat parameters goes in a job file: the flat names
// are the grid's axes and query's keys, and a section takes its own keys (a material
// key in the scene's section is refused; "d_min" there is "diameter.min").
void print_sections(const jobs::Job& job) {
  const jobs::SceneDef* scene = jobs::find_scene(job.scene);
  if (!scene) return;
  const nlohmann::json& params = job.tasks.front().params;
  std::map<std::string, std::string> lists;
  std::set<std::string> placed;
  for (const auto& spec : scene->params) {
    if (!params.contains(spec.name) || !placed.insert(spec.name).second) continue;
    std::string& l = lists[spec.section];
    l += (l.empty() ? "" : ", ") + spec.key + (spec.key == spec.name ? "" : " (" + spec.name + ")");
  }
  std::string top;
  for (const auto& item : params.items())
    if (!placed.count(item.key())) top += (top.empty() ? "" : ", ") + item.key();
  std::cout << "in a job file:\n";
  for (const std::string& section : {std::string("material"), job.scene})
    if (lists.count(section)) std::cout << "  \"" << section << "\": {" << lists[section] << "}\n";
  if (!top.empty()) std::cout << "  top level: " << top << "\n";
}

}  // namespace

void add_validate(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("validate", "Check a job file; print its task count and first task's parameters");
  auto file = std::make_shared<std::string>();
  auto db = std::make_shared<std::string>();
  cmd->add_option("JOB", *file, "job file (JSON)")->required()->check(kPlainPath);
  cmd->add_option("--db", *db, "forecast the work at the speed this database's done tasks of the scene ran at")
      ->check(kDbPath);
  cmd->callback([file, db, &exit_code] {
    exit_code = guarded(*file, [&] {
      const jobs::Job job = jobs::load_job_file(*file);
      if (!db->empty()) require_db(*db);
      std::string axes;
      for (const auto& a : job.axes) axes += (axes.empty() ? "" : " x ") + a;
      std::cout << "job " << job.name << ": scene " << job.scene << ", fidelity " << job.fidelity << "\n"
                << job.tasks.size() << " task(s)"
                << (axes.empty() ? std::string() : " over " + axes) << ", " << job.replicas << " replica(s)\n"
                << "first task (key " << job.tasks.front().key << "):\n"
                << job.tasks.front().params.dump(2) << "\n";
      print_sections(job);
      print_work(job, *db);
      print_notes(*file, job.notes);
      return kOk;
    });
  });
}

}  // namespace demcal::cli
