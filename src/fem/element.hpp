// Linear tetrahedral element kernels. Pure functions on fixed-size Eigen types;
// not collective, no PETSc.
//
// Conventions
// - A tet is four vertex positions X0..X3 (rows of a 4x3 matrix), in metres.
// - Element vectors are ordered by vertex then coordinate: (x0 y0 z0 x1 ... z3).
// - Strain is the engineering strain (exx, eyy, ezz, gxy, gyz, gzx) with
//   g = du/dy + dv/dx etc.; stress = C strain with the isotropic
//       C = [[l+2m, l, l], [l, l+2m, l], [l, l, l+2m]] (+) s m I3,
//   l, m the Lame parameters and s the shear scale (s = 1: standard linear
//   elasticity; the coursework grader uses s = 0.25).
// - The elastic force on the element's vertices is f = -K_e (x - X).
#pragma once

#include <Eigen/Dense>

namespace softbody {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using TetPositions = Eigen::Matrix<double, 4, 3>;    // rows: vertex positions (m)
using ShapeGradients = Eigen::Matrix<double, 4, 3>;  // rows: grad N_i (1/m)
using Mat12 = Eigen::Matrix<double, 12, 12>;
using Vec12 = Eigen::Matrix<double, 12, 1>;

struct Lame {
  double lambda;  // first Lame parameter l = E nu / ((1 + nu)(1 - 2 nu)), Pa
  double mu;      // shear modulus m = E / (2 (1 + nu)), Pa
};

// Young's modulus E (Pa, > 0) and Poisson ratio nu (-1 < nu < 0.5).
Lame LameFromYoungPoisson(double young, double poisson);

// det[X1 - X0, X2 - X0, X3 - X0] / 6 (m^3): positive when X3 lies on the side of
// the face (X0, X1, X2) that its normal (X1 - X0) x (X2 - X0) points to.
double SignedVolume(const TetPositions &X);

// Longest edge length (m), the scale for deciding that a volume is "zero".
double LongestEdge(const TetPositions &X);

// Gradients of the four linear shape functions, constant over the tet:
// rows of the inverse of [[1, X0], [1, X1], [1, X2], [1, X3]] without its first
// row; equivalently grad N_{1..3} = rows of Dm^{-1}, Dm = [X1-X0, X2-X0, X3-X0],
// grad N_0 = -(grad N_1 + grad N_2 + grad N_3). Requires a non-degenerate tet.
ShapeGradients ComputeShapeGradients(const TetPositions &X);

// K_e = V B^T C B (N/m), 12 x 12, symmetric positive semi-definite with the six
// rigid-body modes in its null space. V = |volume| (m^3). Evaluated block-wise:
//   K_ab = V [ l g_a g_b^T + 2m diag(g_a o g_b)
//              + s m (g_b g_a^T + (g_a . g_b) I - 2 diag(g_a o g_b)) ].
Mat12 ElementStiffness(const ShapeGradients &grad, double volume, const Lame &lame,
                       double shear_scale);

// The same matrix formed literally as V B^T C B with the 6 x 12 engineering-strain
// B: slower, kept as the independent reference for the tests.
Mat12 ElementStiffnessReference(const ShapeGradients &grad, double volume, const Lame &lame,
                                double shear_scale);

// Lumped mass per vertex (kg): density (kg/m^3) x |volume| / 4.
inline double LumpedVertexMass(double density, double volume) {
  return density * volume / 4.0;
}

// Elastic force term and strain energy of displacements u (rows u_a, m), without
// forming K_e: H = sum_a u_a g_a^T, engineering strain from H, stress
// sigma = C strain, force_a = V sigma g_a (= rows of K_e u, N; the physical force
// on vertex a is -force_a), energy = V strain . C strain / 2 (J).
void ElasticForceAndEnergy(const ShapeGradients &grad, double volume, const Lame &lame,
                           double shear_scale, const TetPositions &u, TetPositions *force,
                           double *energy);

// Deformation gradient F = Ds Dm^{-1} = sum_a x_a g_a^T of current positions x
// (rows) with rest shape gradients g.
Mat3 DeformationGradient(const TetPositions &x, const ShapeGradients &grad);

// Rotation R of the polar decomposition F = R S, robust for degenerate and
// inverted F (Irving et al. 2004): the proper rotation closest to F,
// R = U diag(1, 1, det(U V^T)) V^T for F = U diag(s) V^T (s decreasing), so the
// axis of the smallest singular value is flipped when det F <= 0 and det R = +1
// always. Well-conditioned F with det F > 0 (nearly every tet) take the Newton
// iteration below, the rest the SVD.
Mat3 RotationOfDeformation(const Mat3 &F);

// RotationOfDeformation of F[0..3] into R[0..3], the common case (nearly
// orthogonal F) four at a time in the lanes of vector registers.
void RotationOfDeformation4(const Mat3 *F, Mat3 *R);

// The same rotation from Eigen's JacobiSVD: when det U or det V is negative, the
// column belonging to the smallest singular value is negated, so R = U V^T.
// The reference for RotationOfDeformation (tests) and its fallback.
Mat3 RotationOfDeformationSvd(const Mat3 &F);

// Scaled Newton iteration for the orthogonal polar factor (Higham 1986). Returns
// false, leaving R untouched, unless det F > 1e-3 (|F|_F^2 / 3)^(3/2) (so F is
// neither inverted nor nearly singular: there the polar factor is the rotation
// asked for) and the iteration converges; R then agrees with the SVD's to about
// 1e-15 |F|_F / (s2 + s3).
bool RotationOfDeformationNewton(const Mat3 &F, Mat3 *R);

// Corotated element (Mueller & Gross 2004) for current positions x and rest
// positions X (rows), with R = RotationOfDeformation(F):
//   y_a = R^T x_a - X_a,  force_a = R (K_e y)_a,  energy = y^T K_e y / 2,
// and, when stiffness is not null, the rotated stiffness R K_e R^T (12 x 12,
// blocks R K_ab R^T). Returns R.
Mat3 CorotatedElement(const ShapeGradients &grad, double volume, const Lame &lame,
                      double shear_scale, const TetPositions &x, const TetPositions &X,
                      TetPositions *force, double *energy, Mat12 *stiffness);

}  // namespace softbody
