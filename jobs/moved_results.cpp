#include "moved_results.hpp"

#include <filesystem>
#include <vector>

namespace demcal::jobs {

std::optional<std::string> find_moved_result(const std::string& stored, const std::string& db) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (stored.empty()) return std::nullopt;
  if (fs::exists(stored, ec)) return stored;
  const fs::path was(stored), dir = fs::weakly_canonical(fs::absolute(db), ec).parent_path();
  const std::vector<fs::path> parts(was.begin(), was.end());
  for (std::size_t from = 1; from < parts.size(); ++from) {
    fs::path tail;
    for (std::size_t k = from; k < parts.size(); ++k) tail /= parts[k];
    const fs::path here = dir / tail;
    if (fs::is_regular_file(here, ec)) return here.string();
  }
  return std::nullopt;
}

}  // namespace demcal::jobs
