#include "shard.hpp"

#include "job_error.hpp"

#include <regex>

namespace demcal::jobs {

Shard parse_shard(const std::string& text) {
  static const std::regex form("([0-9]{1,9})/([0-9]{1,9})");
  std::smatch m;
  if (!std::regex_match(text, m, form))
    throw JobError("--shard", "expected i/N (shard i of N, 1-based, e.g. 2/8), got \"" + text + "\"");
  const long i = std::stol(m[1].str()), n = std::stol(m[2].str());
  if (n < 1 || n > kMaxShards)
    throw JobError("--shard", "the shard count N must be between 1 and " + std::to_string(kMaxShards) + ", got " +
                                  std::to_string(n));
  if (i < 1 || i > n)
    throw JobError("--shard", "the shard index i must be between 1 and N = " + std::to_string(n) + " (shards are 1-based), got " +
                                  std::to_string(i));
  return Shard{static_cast<int>(i), static_cast<int>(n)};
}

}  // namespace demcal::jobs
