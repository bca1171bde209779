#pragma once
// Numbers typed on the command line (--where, --target, --sigma), and when two
// numbers are one value to a reader of the results.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <string>

namespace demcal::jobs {

// The whole of `text` as a decimal number ("30", "-1.5e-3", "inf", "nan"), or false.
// strtod alone also takes leading spaces (" 30" matched where "30 " did not) and
// hexadecimal ("0x1e" read as 30), neither of which a user means as a number.
inline bool parse_decimal(const std::string& text, double& d) {
  if (text.empty() || std::isspace(static_cast<unsigned char>(text.front())) ||
      text.find_first_of("xX") != std::string::npos)
    return false;
  char* end = nullptr;
  d = std::strtod(text.c_str(), &end);
  return end && *end == '\0' && end != text.c_str();
}

// Equal, or apart only past the 12th significant digit: query --where matches them as
// one value, and a grid may not hold both.
inline bool numbers_equal(double a, double b) {
  return a == b || (std::isfinite(a) && std::isfinite(b) && std::abs(a - b) <= 1e-12 * std::max(std::abs(a), std::abs(b)));
}

}  // namespace demcal::jobs
