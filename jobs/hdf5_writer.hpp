#pragma once
// Per-task HDF5 files: every time series as a group /series/<name> holding one
// chunked, deflated 1-D dataset per column (the order is in the group's "columns"
// attribute), the task parameters as the root attribute "params", and optional
// particle snapshots in the H5Part layout (/Step#<n>/x, y, z, radius, vx, vy, vz, wx,
// wy, wz, fixed, with attributes TimeValue and label) that ParaView's H5Part reader
// opens. The scenes' snapshot points are listed in engine/observer.hpp.
#include "engine/observer.hpp"

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace demcal::jobs {

struct Snapshot {
  std::string label;
  double time = 0;
  std::vector<double> x, y, z, radius, vx, vy, vz, wx, wy, wz;
  std::vector<double> fixed;  // 1 for a grain that never moves (a rough floor), else 0
};

// Collects snapshots from a running scene (only when asked for: they are big).
class SnapshotObserver : public engine::Observer {
 public:
  explicit SnapshotObserver(bool keep) : keep_(keep) {}
  void on_snapshot(const std::string& label, double time, const engine::Particles& p) override;
  std::vector<Snapshot> snapshots;

 private:
  bool keep_;
};

// Which task a file belongs to (root attributes).
struct TaskFileInfo {
  std::string scene;
  std::string task_key;  // the task's key in the database (db::task_key)
  std::int64_t task_id = 0;
  std::string status = "done";  // or "failed": a failed run's series end where it stopped
  std::string message;          // a failed task's reason, a finished one's warnings
};

// Root attributes: scene, params (JSON), task_key, task_id, status, message (when
// any) and physics_version; each
// series column and snapshot dataset carries a "units" attribute (SI; "1" for a pure
// number). Written to a part of this process's own (`path`.<host>-pidns<n>-<pid>.part) and
// renamed into place when whole; throws OutputWriteError naming the path and the
// reason when it cannot be written (the runner stops on it).
void write_task_hdf5(const std::string& path, const TaskFileInfo& info, const nlohmann::json& params,
                     const std::vector<engine::Series>& series, const std::vector<Snapshot>& snapshots);
// The task key a file was written for ("" for a file from before keys were written).
std::string read_task_key(const std::string& path);

// The group that holds snapshot `step` (0-based): "Step#<step>", H5Part's name.
std::string snapshot_group(std::size_t step);

// Reads one series back (for plotting); throws std::runtime_error when absent.
engine::Series read_series(const std::string& path, const std::string& name);
std::vector<std::string> series_names(const std::string& path);

}  // namespace demcal::jobs
