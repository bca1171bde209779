#include "worker.hpp"

#include "child_process.hpp"
#include "hdf5_writer.hpp"
#include "part_file.hpp"
#include "xdmf_writer.hpp"
#include "scene_registry.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace demcal::jobs {
namespace {

// JSON has no inf or NaN; a diverged drift is a legitimate value, so spell it out.
nlohmann::json encode(double v) {
  if (std::isfinite(v)) return v;
  if (std::isnan(v)) return "nan";
  return v > 0 ? "inf" : "-inf";
}
double decode(const nlohmann::json& v) {
  if (v.is_number()) return v.get<double>();
  const std::string s = v.get<std::string>();
  if (s == "inf") return INFINITY;
  if (s == "-inf") return -INFINITY;
  return NAN;
}

void test_abort_hook(std::size_t index) {
  const char* env = std::getenv("DEMCAL_TEST_ABORT_TASK");
  if (env && *env && std::to_string(index) == env) std::abort();
}

// The snapshots' Xdmf description beside the HDF5 file: a viewing aid, so a failure
// to write it is the task's warning (or part of its error), never the loss of a
// finished task's results; without snapshots an earlier run's description goes.
void add_xdmf(const std::string& h5_path, const std::vector<Snapshot>& snapshots, nlohmann::json& out) {
  const std::string xmf = xdmf_path_for(h5_path);
  std::error_code ec;
  if (snapshots.empty()) {
    std::filesystem::remove(xmf, ec);
    return;
  }
  try {
    write_snapshot_xdmf(xmf, std::filesystem::path(h5_path).filename().string(), snapshots);
    out["artifacts"].push_back(nlohmann::json::array({"xdmf", xmf}));
  } catch (const std::runtime_error& e) {
    std::filesystem::remove(xmf, ec);  // no description of another run's snapshots
    const char* key = out.value("status", "") == "done" ? "warnings" : "error";
    const std::string before = out.value(key, "");
    out[key] = before + (before.empty() ? "" : "; ") + e.what() + " (the HDF5 file and the results are kept)";
  }
}

nlohmann::json run_scene(const WorkerTask& t) {
  nlohmann::json out;
  const SceneDef* scene = find_scene(t.scene);
  if (!scene) throw std::runtime_error("unknown scene " + t.scene);
  SnapshotObserver obs(t.snapshots);
  const SceneOutput r = scene->run(t.params, RunContext{t.threads, &obs});
  nlohmann::json metrics = nlohmann::json::array();
  for (const auto& [name, value] : r.metrics) metrics.push_back({name, encode(value)});
  out["metrics"] = metrics;
  TaskFileInfo info;
  info.scene = t.scene;
  info.task_key = t.task_key;
  info.task_id = t.task_id;
  if (r.outcome.ok()) {
    out["status"] = "done";
    // A finished task's warnings (not quasi-static, a diagnostic knob on, ...) travel
    // with it: the metrics stand, and the user must hear what they stand on. A scene
    // that ends ok joins its warnings into the message (SceneOutcome).
    if (!r.outcome.message.empty()) out["warnings"] = r.outcome.message;
    info.message = r.outcome.message;
  } else {
    out["status"] = "failed";
    out["error"] = std::string(engine::to_string(r.outcome.status)) + " in stage " + r.outcome.failed_stage + ": " +
                   r.outcome.message;
    info.status = "failed";
    info.message = out["error"].get<std::string>();
  }
  // The file says how the run ended: a failed run's series stop where it did.
  write_task_hdf5(t.h5_path, info, t.params, r.series, obs.snapshots);
  out["artifacts"] = nlohmann::json::array({nlohmann::json::array({"hdf5", t.h5_path})});
  add_xdmf(t.h5_path, obs.snapshots, out);
  return out;
}

}  // namespace

std::string task_file_name(std::int64_t task_id, const std::string& task_key) {
  return std::to_string(task_id) + (task_key.empty() ? "" : "-" + task_key.substr(0, 8)) + ".h5";
}

int run_worker(const WorkerTask& t) {
  test_abort_hook(t.index);
  const auto t0 = std::chrono::steady_clock::now();
  nlohmann::json out;
  bool output_written = true;
  try {
    out = run_scene(t);
  } catch (const std::exception& e) {
    out = {{"status", "failed"}, {"error", e.what()}, {"metrics", nlohmann::json::array()},
           {"artifacts", nlohmann::json::array()}};
    // The folder's fault only if it took no file when the write failed, or takes none
    // now: a cause of this task's own (a folder in the way of its name) fails the
    // task alone.
    if (const auto* w = dynamic_cast<const OutputWriteError*>(&e))
      output_written = !w->folder_full() && folder_takes_a_file(std::filesystem::path(t.h5_path).parent_path());
  }
  out["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::string tmp = t.result_path + ".tmp";
  {
    std::ofstream f(tmp, std::ios::trunc);
    f << out.dump();
    f.close();  // the write reaches the disk (or fails) here, before the check
    if (!f) {
      std::remove(tmp.c_str());  // no empty .tmp left behind on a full disk
      return kWorkerResultUnwritable;
    }
  }
  // rename is atomic: the parent sees a whole result or none.
  if (std::rename(tmp.c_str(), t.result_path.c_str()) == 0) return output_written ? 0 : kWorkerOutputUnwritable;
  std::remove(tmp.c_str());
  return kWorkerResultUnwritable;
}

bool worker_left_result(int wait_status) {
  return WIFEXITED(wait_status) && (WEXITSTATUS(wait_status) == 0 || WEXITSTATUS(wait_status) == kWorkerOutputUnwritable);
}

bool worker_output_unwritable(int wait_status) {
  return WIFEXITED(wait_status) &&
         (WEXITSTATUS(wait_status) == kWorkerResultUnwritable || WEXITSTATUS(wait_status) == kWorkerOutputUnwritable);
}

std::string worker_failure(int wait_status, const std::string& result_path) {
  if (WIFSIGNALED(wait_status)) {
    const char* abbrev = sigabbrev_np(WTERMSIG(wait_status));
    return "worker killed by " + (abbrev ? "SIG" + std::string(abbrev) : "signal " + std::to_string(WTERMSIG(wait_status)));
  }
  if (WIFEXITED(wait_status) && WEXITSTATUS(wait_status) == kWorkerResultUnwritable)
    return "the worker ran the task but could not write its result to " + result_path + ": the metrics are lost (" +
           why_folder_takes_no_file(std::filesystem::path(result_path).parent_path()) + ")";
  return "worker exited with status " + std::to_string(WIFEXITED(wait_status) ? WEXITSTATUS(wait_status) : -1) +
         " without a result";
}

std::optional<db::Outcome> read_worker_result(const std::string& path) {
  std::ifstream f(path);
  if (!f) return std::nullopt;
  std::stringstream text;
  text << f.rdbuf();
  return parse_worker_result(text.str());
}

std::optional<db::Outcome> parse_worker_result(const std::string& text) {
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    db::Outcome o;
    o.status = j.at("status").get<std::string>();
    o.error = j.value("error", "");
    if (o.error.empty() && j.contains("warnings")) o.error = db::warning_message(j.at("warnings").get<std::string>());
    o.wall_s = j.at("wall_s").get<double>();
    for (const auto& m : j.at("metrics")) o.metrics.emplace_back(m.at(0).get<std::string>(), decode(m.at(1)));
    for (const auto& a : j.at("artifacts")) o.artifacts.emplace_back(a.at(0).get<std::string>(), a.at(1).get<std::string>());
    return o;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

std::string run_forked(const WorkerTask& t, double tick_s, const std::function<void()>& tick) {
  std::error_code gone;  // the folder may be gone: the worker then says so
  std::filesystem::remove(t.result_path, gone);
  std::cout.flush();
  std::cerr.flush();
  std::fflush(nullptr);
  const auto t0 = std::chrono::steady_clock::now();
  // As in the local runner: the child dies with its parent, never touches anything
  // it inherited (here: MPI) and leaves with _exit().
  const pid_t pid = fork_bound_to_parent(4);
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    signal(SIGINT, SIG_IGN);
    signal(SIGTERM, SIG_DFL);
    _exit(run_worker(t));
  }
  int st = 0;
  auto last_tick = t0;
  for (;;) {
    const pid_t w = waitpid(pid, &st, WNOHANG);
    if (w == pid) break;
    if (w < 0 && errno != EINTR) throw std::runtime_error("waitpid failed");
    const auto now = std::chrono::steady_clock::now();
    if (std::chrono::duration<double>(now - last_tick).count() >= tick_s) {
      last_tick = now;
      if (tick) tick();
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::string text;
  if (worker_left_result(st)) {
    std::ifstream f(t.result_path);
    std::stringstream buf;
    buf << f.rdbuf();
    text = buf.str();
  }
  std::filesystem::remove(t.result_path, gone);
  nlohmann::json out;
  if (!text.empty() && parse_worker_result(text)) {
    if (!worker_output_unwritable(st)) return text;
    out = nlohmann::json::parse(text);
  } else {
    out = {{"status", "failed"}, {"error", worker_failure(st, t.result_path)}, {"wall_s", wall},
           {"metrics", nlohmann::json::array()}, {"artifacts", nlohmann::json::array()}};
  }
  if (worker_output_unwritable(st)) out[kOutputUnwritableKey] = true;  // rank 0 stops handing out work
  return out.dump();
}

}  // namespace demcal::jobs
