#pragma once
// How a scene ended. A failed scene still returns its result, with the stage that
// failed and why, and never a metric computed from a broken run.
#include <string>
#include <utility>
#include <vector>

namespace demcal::engine {

// invalid: the run ended, but what it ran was not the test it measures (a triaxial
// whose servo lost sigma3, or whose sample lost its contact network): no metric of it
// may pass as a result.
enum class SceneStatus { ok, unstable, not_converged, not_settled, invalid };

inline const char* to_string(SceneStatus s) {
  switch (s) {
    case SceneStatus::ok: return "ok";
    case SceneStatus::unstable: return "unstable";
    case SceneStatus::not_converged: return "not_converged";
    case SceneStatus::not_settled: return "not_settled";
    case SceneStatus::invalid: return "invalid";
  }
  return "unknown";
}

struct SceneOutcome {
  SceneStatus status = SceneStatus::ok;
  std::string failed_stage;  // empty when ok
  std::string message;       // why it failed, or warnings when ok
  std::vector<std::string> warnings;
  bool ok() const { return status == SceneStatus::ok; }
  // Appends the warnings to the message, "; " between them: the text a task stores
  // (which is why no warning may contain "; ").
  void join_warnings() {
    for (const auto& w : warnings) message += (message.empty() ? "" : "; ") + w;
  }
};

using Metrics = std::vector<std::pair<std::string, double>>;

}  // namespace demcal::engine
