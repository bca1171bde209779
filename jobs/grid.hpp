#pragma once
// Grid expansion: the Cartesian product of the axes, times replicas (seed + r).
#include "validate.hpp"

#include <cstdint>
#include <nlohmann/json.hpp>
#include <vector>

namespace demcal::jobs {

// Number of tasks the product gives, saturating at grid_size_cap instead of
// overflowing.
constexpr std::uint64_t grid_size_cap = std::uint64_t(1) << 62;
std::uint64_t grid_size(const ParamSet& set, int replicas);

// Flat parameters of every task; the last axis varies fastest, replicas innermost.
std::vector<nlohmann::json> expand(const ParamSet& set, int replicas, std::uint64_t seed);

}  // namespace demcal::jobs
