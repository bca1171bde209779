#include "particles.hpp"

namespace demcal::engine {
namespace {

template <class T>
void keep(std::vector<T>& v, const std::vector<std::uint8_t>& drop) {
  std::size_t out = 0;
  for (std::size_t i = 0; i < v.size(); ++i)
    if (!drop[i]) v[out++] = v[i];
  v.resize(out);
}

template <class T>
void permute(std::vector<T>& v, const std::vector<std::size_t>& order) {
  std::vector<T> tmp(order.size());
  for (std::size_t i = 0; i < order.size(); ++i) tmp[i] = v[order[i]];
  v.swap(tmp);
}

}  // namespace

void Particles::remove_if(const std::vector<std::uint8_t>& drop) {
  keep(x, drop), keep(v, drop), keep(w, drop), keep(f, drop), keep(t, drop);
  keep(r, drop), keep(m, drop), keep(inv_m, drop), keep(inv_i, drop), keep(fixed, drop);
}

void Particles::reorder(const std::vector<std::size_t>& order) {
  permute(x, order), permute(v, order), permute(w, order), permute(f, order), permute(t, order);
  permute(r, order), permute(m, order), permute(inv_m, order), permute(inv_i, order), permute(fixed, order);
}

}  // namespace demcal::engine
