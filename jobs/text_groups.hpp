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

// "task 3", "tasks 1, 2, 5" or "tasks 1, 2, ... (12)"; "all 9 tasks" when the ids
// are every one of `of` (0: unknown). At most `shown` ids before the count. `mark`
// goes before each id: "#" for indices in the job's grid, which count from 0 (the
// runner's log writes "task 4 (#3: ...)"), so that they do not read as task ids.
inline std::string task_list(const std::vector<std::int64_t>& ids, std::size_t of = 0, std::size_t shown = 8,
                             const char* mark = "") {
  if (of > 1 && ids.size() == of) return "all " + std::to_string(of) + " tasks";
  std::string s = ids.size() > 1 ? "tasks " : "task ";
  const std::size_t listed = ids.size() > shown + 1 ? shown : ids.size();
  for (std::size_t j = 0; j < listed; ++j) s += (j ? ", " : "") + std::string(mark) + std::to_string(ids[j]);
  if (listed < ids.size()) s += ", ... (" + std::to_string(ids.size()) + ")";
  return s;
}

}  // namespace demcal::jobs
