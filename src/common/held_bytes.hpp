// Bytes a container holds on the heap (its capacity, not its size), for the run
// summary's count of what a rank keeps of the whole scene. Not collective.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace softbody {

template <class T>
int64_t HeldBytes(const std::vector<T> &v) {
  return static_cast<int64_t>(v.capacity() * sizeof(T));
}

// A vector of vectors: the outer array and every inner one.
template <class T>
int64_t HeldBytes(const std::vector<std::vector<T>> &v) {
  int64_t bytes = static_cast<int64_t>(v.capacity() * sizeof(std::vector<T>));
  for (const std::vector<T> &inner : v) bytes += HeldBytes(inner);
  return bytes;
}

template <class Derived>
int64_t HeldBytes(const Eigen::PlainObjectBase<Derived> &m) {
  return static_cast<int64_t>(m.size() * sizeof(typename Derived::Scalar));
}

}  // namespace softbody
