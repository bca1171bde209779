#pragma once
// Short forms of stored messages, for one line of a fit's or an envelope's output.
#include <string>

namespace demcal::calibrate {

// The first of a task's warnings (the run joins them with "; "), "(and more)" after
// it when others follow.
inline std::string first_warning(const std::string& warnings) {
  const auto semi = warnings.find("; ");
  return semi == std::string::npos ? warnings : warnings.substr(0, semi) + " (and more)";
}

// Whether a task's stored warnings say its critical-state window was not at critical
// state (the triaxial scene's "not at critical state over ...", which
// scripts/seed-study.sh looks for too).
inline bool says_not_at_critical_state(const std::string& warnings) {
  return warnings.find("not at critical state") != std::string::npos;
}

// Text longer than `max` characters cut at a word, " ..." after it.
inline std::string cut_at_word(const std::string& text, std::size_t max) {
  return text.size() > max ? text.substr(0, text.rfind(' ', max - 4)) + " ..." : text;
}

}  // namespace demcal::calibrate
