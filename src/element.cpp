#include "element.hpp"

#include <cmath>

namespace softbody {

Lame LameFromYoungPoisson(double young, double poisson) {
  return {young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson)),
          young / (2.0 * (1.0 + poisson))};
}

static Mat3 EdgeMatrix(const TetPositions &X) {
  Mat3 Dm;
  Dm.col(0) = (X.row(1) - X.row(0)).transpose();
  Dm.col(1) = (X.row(2) - X.row(0)).transpose();
  Dm.col(2) = (X.row(3) - X.row(0)).transpose();
  return Dm;
}

double SignedVolume(const TetPositions &X) { return EdgeMatrix(X).determinant() / 6.0; }

double LongestEdge(const TetPositions &X) {
  double longest = 0;
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b) longest = std::max(longest, (X.row(a) - X.row(b)).norm());
  return longest;
}

ShapeGradients ComputeShapeGradients(const TetPositions &X) {
  const Mat3 Dm_inv = EdgeMatrix(X).inverse();
  ShapeGradients grad;
  grad.row(1) = Dm_inv.row(0);
  grad.row(2) = Dm_inv.row(1);
  grad.row(3) = Dm_inv.row(2);
  grad.row(0) = -(grad.row(1) + grad.row(2) + grad.row(3));
  return grad;
}

Mat12 ElementStiffness(const ShapeGradients &grad, double volume, const Lame &lame,
                       double shear_scale) {
  const double l = lame.lambda, m = lame.mu, sm = shear_scale * lame.mu;
  Mat12 K;
  for (int a = 0; a < 4; ++a) {
    const Vec3 ga = grad.row(a).transpose();
    for (int b = a; b < 4; ++b) {
      const Vec3 gb = grad.row(b).transpose();
      const Vec3 product = ga.cwiseProduct(gb);
      Mat3 block = l * ga * gb.transpose() + sm * gb * ga.transpose();
      block.diagonal().array() += sm * ga.dot(gb);
      block.diagonal() += (2.0 * m - 2.0 * sm) * product;
      block *= volume;
      K.block<3, 3>(3 * a, 3 * b) = block;
      if (b != a) K.block<3, 3>(3 * b, 3 * a) = block.transpose();
    }
  }
  return K;
}

void ElasticForceAndEnergy(const ShapeGradients &grad, double volume, const Lame &lame,
                           double shear_scale, const TetPositions &u, TetPositions *force,
                           double *energy) {
  // Displacement gradient du_i/dX_j from differences to vertex 0 (the gradients
  // sum to zero, so this is the same H, without the round-off of a large common
  // translation: stiff bodies far from their rest place keep exact energies).
  const TetPositions relative = u.rowwise() - u.row(0);
  const Mat3 H = relative.transpose() * grad;
  const double trace = H.trace(), sm = shear_scale * lame.mu;
  Mat3 stress = sm * (H + H.transpose());
  stress.diagonal() = (lame.lambda * trace) * Vec3::Ones() + 2.0 * lame.mu * H.diagonal();
  *force = volume * grad * stress;  // row a: V (sigma g_a)^T, sigma symmetric
  // strain . stress: normal parts H_ii sigma_ii, shear parts gamma_ij tau_ij.
  double density = 0;
  for (int i = 0; i < 3; ++i) density += H(i, i) * stress(i, i);
  density += (H(0, 1) + H(1, 0)) * stress(0, 1) + (H(1, 2) + H(2, 1)) * stress(1, 2) +
             (H(2, 0) + H(0, 2)) * stress(2, 0);
  *energy = 0.5 * volume * density;
}

Mat3 DeformationGradient(const TetPositions &x, const ShapeGradients &grad) {
  return x.transpose() * grad;
}

Mat3 RotationOfDeformation(const Mat3 &F) {
  const Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU(), V = svd.matrixV();
  // Eigen orders singular values decreasingly: column 2 is the smallest.
  if (U.determinant() < 0) U.col(2) *= -1.0;
  if (V.determinant() < 0) V.col(2) *= -1.0;
  return U * V.transpose();
}

Mat3 CorotatedElement(const ShapeGradients &grad, double volume, const Lame &lame,
                      double shear_scale, const TetPositions &x, const TetPositions &X,
                      TetPositions *force, double *energy, Mat12 *stiffness) {
  const Mat3 R = RotationOfDeformation(DeformationGradient(x, grad));
  const TetPositions y = x * R - X;  // rows: R^T x_a - X_a
  TetPositions local_force;
  ElasticForceAndEnergy(grad, volume, lame, shear_scale, y, &local_force, energy);
  *force = local_force * R.transpose();  // rows: (R f_a)^T
  if (stiffness) {
    *stiffness = ElementStiffness(grad, volume, lame, shear_scale);
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        stiffness->block<3, 3>(3 * a, 3 * b) = R * stiffness->block<3, 3>(3 * a, 3 * b) * R.transpose();
  }
  return R;
}

Mat12 ElementStiffnessReference(const ShapeGradients &grad, double volume, const Lame &lame,
                                double shear_scale) {
  Eigen::Matrix<double, 6, 12> B = Eigen::Matrix<double, 6, 12>::Zero();
  for (int a = 0; a < 4; ++a) {
    const double gx = grad(a, 0), gy = grad(a, 1), gz = grad(a, 2);
    B(0, 3 * a + 0) = gx;  // exx
    B(1, 3 * a + 1) = gy;  // eyy
    B(2, 3 * a + 2) = gz;  // ezz
    B(3, 3 * a + 0) = gy;  // gxy = du/dy + dv/dx
    B(3, 3 * a + 1) = gx;
    B(4, 3 * a + 1) = gz;  // gyz = dv/dz + dw/dy
    B(4, 3 * a + 2) = gy;
    B(5, 3 * a + 0) = gz;  // gzx = dw/dx + du/dz
    B(5, 3 * a + 2) = gx;
  }
  Eigen::Matrix<double, 6, 6> C = Eigen::Matrix<double, 6, 6>::Zero();
  C.topLeftCorner<3, 3>().setConstant(lame.lambda);
  C.topLeftCorner<3, 3>().diagonal().array() += 2.0 * lame.mu;
  C.bottomRightCorner<3, 3>().diagonal().setConstant(shear_scale * lame.mu);
  return volume * B.transpose() * C * B;
}

}  // namespace softbody
