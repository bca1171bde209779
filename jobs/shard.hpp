#pragma once
// A deterministic split of a job's task list for batch schedulers
// (`demcal run JOB --shard i/N`): the task at expansion index k (0-based) belongs
// to shard (k mod N) + 1. Round-robin rather than contiguous blocks, so tasks
// that differ along the slowest-varying grid axis (often the costly one: particle
// count, pressure) are spread over all shards. Depends only on the job file.
#include <cstddef>
#include <string>

namespace demcal::jobs {

struct Shard {
  int index = 0;  // 1-based; 0 when not sharded
  int count = 0;
  bool active() const { return count > 0; }
  bool contains(std::size_t task_index) const {
    return !active() || static_cast<int>(task_index % static_cast<std::size_t>(count)) + 1 == index;
  }
  std::string label() const { return std::to_string(index) + "/" + std::to_string(count); }
};

constexpr int kMaxShards = 100000;

// "i/N" with 1 <= i <= N <= kMaxShards; throws JobError("--shard", reason) otherwise.
Shard parse_shard(const std::string& text);

}  // namespace demcal::jobs
