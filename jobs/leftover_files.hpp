#pragma once
// Files a killed runner leaves in a job's output folder: its workers' result files
// (".task-ID.RUNNER.result.json" and its ".tmp"; an MPI farm's worker ranks write
// ".task-ID.RUNNER.rankN.result.json") and the HDF5 parts they were writing
// ("NAME.HOST-PID.part"). A runner that dies by SIGKILL cannot remove them, and its
// tasks run again elsewhere under other names, so nothing else ever would.
#include <filesystem>
#include <string>

namespace demcal::db {
class Store;
}

namespace demcal::jobs {

class BeatWatch;

// Removes from `dir` the leftovers of runners that are gone: on this host (and pid
// namespace) by their processes, elsewhere by their heartbeats as `watch` has seen
// them (a watch new to a runner believes it alive for kRunnerConfirmS: a run sweeps
// again on its timer). Files of live runners (this one, `own_tag`, another run of the
// job) and of writers it cannot judge (a part written in another namespace or host, a
// runner it has no token of) are kept. Returns how many it removed.
int remove_leftovers_of_dead_runners(const std::filesystem::path& dir, db::Store& store, const std::string& own_tag,
                                     BeatWatch* watch);

// What a run says when it removed `n` such files from `dir` (no newline).
std::string leftovers_removed_line(int n, const std::filesystem::path& dir);

}  // namespace demcal::jobs
