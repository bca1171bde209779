#pragma once
// Enumerations read back from their names (job files, stored parameters): the value
// whose to_string(value) is `name`, among every value listed.
#include <cstddef>
#include <string>

namespace demcal::engine {

template <class E, std::size_t N>
bool parse_by_name(const std::string& name, const E (&values)[N], E& out) {
  for (E e : values)
    if (name == to_string(e)) {
      out = e;
      return true;
    }
  return false;
}

}  // namespace demcal::engine
