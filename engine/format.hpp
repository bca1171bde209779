#pragma once
// Numbers in messages: the shortest form at a few significant digits ("0.0399",
// "1e+09"), as a stream writes them.
#include <sstream>
#include <string>

namespace demcal::engine {

inline std::string fmt(double v, int precision = 4) {
  std::ostringstream os;
  os.precision(precision);
  os << v;
  return os.str();
}

}  // namespace demcal::engine
