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
