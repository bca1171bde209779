#pragma once
// Distinct texts (warnings, errors, advice) with the tasks that carry each, in order
// of first appearance: a message repeated for many tasks is said once, naming them.
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

namespace demcal::jobs {

struct TextGroups {
  std::vector<std::string> texts;
  std::vector<std::vector<std::int64_t>> tasks;  // per text, the tasks carrying it

  // Records `task` under `text`; returns the text's position (0-based).
  std::size_t add(const std::string& text, std::int64_t task) {
    auto it = std::find(texts.begin(), texts.end(), text);
    if (it == texts.end()) {
      texts.push_back(text);
      tasks.emplace_back();
      it = texts.end() - 1;
    }
    const auto k = static_cast<std::size_t>(it - texts.begin());
    tasks[k].push_back(task);
    return k;
  }
};

// "task 3" or "tasks 1, 2, ... (12)": at most `shown` ids, then the count.
inline std::string task_list(const std::vector<std::int64_t>& ids, std::size_t shown = 8) {
  std::string s = ids.size() > 1 ? "tasks " : "task ";
  for (std::size_t j = 0; j < ids.size() && j < shown; ++j) s += (j ? ", " : "") + std::to_string(ids[j]);
  if (ids.size() > shown) s += ", ... (" + std::to_string(ids.size()) + ")";
  return s;
}

}  // namespace demcal::jobs
