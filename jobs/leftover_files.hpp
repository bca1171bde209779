#pragma once
// Files a killed runner leaves in a job's output folder: its workers' result files
// (".task-ID.RUNNER.result.json" and its ".tmp") and the HDF5 parts they were writing
// ("NAME.HOST-PID.part"). A runner that dies by SIGKILL cannot remove them, and its
// tasks run again elsewhere under other names, so nothing else ever would.
#include <filesystem>
#include <string>

namespace demcal::db {
class Store;
}

namespace demcal::jobs {

class BeatWatch;

// Removes from `dir` the leftovers of runners that `store`'s heartbeats and this
// host's processes say are gone; files of live runners (this one, `own_tag`, another
// run of the job on this or another host) and of writers it cannot judge (a part
// of another host, a runner it has no token of) are kept. Returns how many it removed.
int remove_leftovers_of_dead_runners(const std::filesystem::path& dir, db::Store& store, const std::string& own_tag,
                                     BeatWatch* watch);

}  // namespace demcal::jobs
