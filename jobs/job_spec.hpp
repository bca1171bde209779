#pragma once
// A job file, read and fully validated: its top-level settings and the resolved
// parameters and key of every task it expands to. Nothing here touches the store,
// so an invalid job is rejected before anything is written.
#include <cstdint>
#include <nlohmann/json.hpp>
#include <cstddef>
#include <string>
#include <vector>

namespace demcal::jobs {

// Refuse grids beyond this: almost certainly a mistake, and the store would balloon.
constexpr std::uint64_t kMaxTasks = 100000;

struct Task {
  std::size_t index = 0;   // position in the expansion
  nlohmann::json params;   // flat, resolved: {"theta_deg": 30.0, ..., "seed": 7}
  std::string key;         // content key (task_key)
};

struct Job {
  std::string name;
  std::string scene;
  std::string fidelity;  // "quick" | "standard" | "reference"
  std::string source;    // file name, for messages
  nlohmann::json spec;   // the job as written
  int replicas = 1;
  std::uint64_t seed = 1;
  int threads = 0;  // engine threads per task; 0: the runner decides
  bool snapshots = false;
  std::vector<std::string> axes;  // grid axes, in expansion order
  std::vector<Task> tasks;
  std::vector<std::string> notes;  // what the file says that is legal but easy to miss
};

// A job file is a few kilobytes; anything past this is not one.
constexpr std::size_t kMaxJobFileBytes = std::size_t{16} << 20;

// Throw JobError naming the JSON path (or "" for whole-file problems such as a
// missing file, one larger than kMaxJobFileBytes, or malformed JSON, with line and
// column).
Job load_job_file(const std::string& path);
Job parse_job(const std::string& text, const std::string& source);
// How many tasks the job expands to, read without resolving (or checking) each task:
// what `status` compares a database's share of a job with. Throws JobError as
// parse_job does for a file it cannot read at all.
std::uint64_t count_tasks(const std::string& text, const std::string& source);

}  // namespace demcal::jobs
