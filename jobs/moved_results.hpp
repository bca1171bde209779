#pragma once
// A database and its results moved together (a cluster's results copied to a laptop,
// a merged database with its parts/ folder): the stored paths, absolute, name the old
// place. The folder the database is in is searched for a stored path's tail, the
// longest first: demcal-out/JOB/FILE beside it, parts/demcal-out/... of a merge.
#include <optional>
#include <string>

namespace demcal::jobs {

// Where the file stored as `stored` is now: `stored` while it exists, else the first
// tail of it found under the folder of the database `db`; nullopt when neither.
std::optional<std::string> find_moved_result(const std::string& stored, const std::string& db);

}  // namespace demcal::jobs
