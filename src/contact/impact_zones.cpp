#include "contact/impact_zones.hpp"

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>

namespace softbody {

namespace {

// Inertia eigenvalues below this fraction of the largest count as zero: a
// zone of collinear vertices (two, say) has none about its axis.
constexpr double kSingularInertia = 1e-12;

// The minimum-norm solution of I theta = L for the symmetric inertia I.
Point PseudoSolve(const Eigen::Matrix3d &inertia, const Point &momentum) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(inertia);
  const Eigen::Vector3d lambda = eigen.eigenvalues();
  Point theta = Point::Zero();
  for (int k = 0; k < 3; ++k)
    if (lambda[k] > kSingularInertia * lambda[2]) {
      const Point q = eigen.eigenvectors().col(k);
      theta += q.dot(momentum) / lambda[k] * q;
    }
  return theta;
}

}  // namespace

void ImpactZones::Reset(int32_t num_vertices) {
  parent_.resize(num_vertices);
  for (int32_t v = 0; v < num_vertices; ++v) parent_[v] = v;
  immobile_.assign(num_vertices, 0);
  members_.assign(num_vertices, {});
  touched_.clear();
}

int32_t ImpactZones::Add() {
  const auto vertex = static_cast<int32_t>(parent_.size());
  parent_.push_back(vertex);
  immobile_.push_back(0);
  members_.emplace_back();
  return vertex;
}

int32_t ImpactZones::Find(int32_t vertex) {
  while (parent_[vertex] != vertex) vertex = parent_[vertex] = parent_[parent_[vertex]];
  return vertex;
}

bool ImpactZones::InOneMobileZone(const int32_t *vertices, int count) {
  const int32_t root = Find(vertices[0]);
  if (members_[root].empty() || immobile_[root]) return false;
  for (int k = 1; k < count; ++k)
    if (Find(vertices[k]) != root) return false;
  return true;
}

void ImpactZones::Merge(const int32_t *vertices, int count, bool immobile) {
  int32_t root = Find(vertices[0]);
  for (int k = 0; k < count; ++k) {
    int32_t other = Find(vertices[k]);
    if (members_[root].empty()) members_[root] = {root};
    if (members_[other].empty()) members_[other] = {other};
    if (other != root) {
      if (members_[other].size() > members_[root].size()) std::swap(root, other);
      parent_[other] = root;
      members_[root].insert(members_[root].end(), members_[other].begin(), members_[other].end());
      members_[other].clear();
      members_[other].shrink_to_fit();
      immobile_[root] = immobile_[root] || immobile_[other];
    }
  }
  immobile_[root] = immobile_[root] || immobile;
  touched_.push_back(root);
}

std::vector<int32_t> ImpactZones::Move(const std::vector<Point> &start,
                                       const std::vector<double> &mass, std::vector<Point> *end) {
  for (int32_t &root : touched_) root = Find(root);
  std::sort(touched_.begin(), touched_.end());
  touched_.erase(std::unique(touched_.begin(), touched_.end()), touched_.end());
  std::vector<int32_t> changed;
  for (const int32_t root : touched_) {
    const std::vector<int32_t> &members = members_[root];
    const std::vector<Point> before = [&] {
      std::vector<Point> positions;
      for (const int32_t v : members) positions.push_back((*end)[v]);
      return positions;
    }();
    if (immobile_[root])
      for (const int32_t v : members) (*end)[v] = start[v];
    else
      MoveRigidly(members, start, mass, end);
    for (size_t k = 0; k < members.size(); ++k)
      if ((*end)[members[k]] != before[k]) changed.push_back(members[k]);
  }
  touched_.clear();
  return changed;
}

void ImpactZones::MoveRigidly(const std::vector<int32_t> &members, const std::vector<Point> &start,
                              const std::vector<double> &mass, std::vector<Point> *end) const {
  double total = 0;
  Point c0 = Point::Zero(), c1 = Point::Zero();
  for (const int32_t v : members) {
    total += mass[v];
    c0 += mass[v] * start[v];
    c1 += mass[v] * (*end)[v];
  }
  c0 /= total;
  c1 /= total;
  Point momentum = Point::Zero();
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();
  for (const int32_t v : members) {
    const Point r = start[v] - c0, u = (*end)[v] - start[v] - (c1 - c0);
    momentum += mass[v] * r.cross(u);
    inertia += mass[v] * (r.squaredNorm() * Eigen::Matrix3d::Identity() - r * r.transpose());
  }
  const Point theta = PseudoSolve(inertia, momentum);
  const double angle = theta.norm();
  const Eigen::Matrix3d rotation = angle > 0
                                       ? Eigen::AngleAxisd(angle, theta / angle).toRotationMatrix()
                                       : Eigen::Matrix3d::Identity();
  for (const int32_t v : members) (*end)[v] = c1 + rotation * (start[v] - c0);
}

}  // namespace softbody
