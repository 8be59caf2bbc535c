#pragma once
// VMCS 1999 (VMCS, 1999): the cutting force of an end mill by Kline's mechanistic
// model. The tool is cut into M axial discs of height Dz; flute k of disc i at tool
// rotation angle θ sits at the immersion angle
//   φ(i, θ, k) = θ + k·2π/N − (i + 1/2)·Dz·tan(h)/R          (paper eq. 3, helix lag)
// and cuts the chip t_c = f_t·sin φ (eq. 1) while φ lies in the engaged arc. Its
// elemental forces (eq. 4 / eq. 12) are projected onto X/Y (eq. 5) and summed over
// the engaged elements (eq. 6).
//
// Conventions (Altintas, "Manufacturing Automation"; the paper's eq. 5 is the same
// projection with its angle measured from another axis): feed along +X, the tool
// turns clockwise seen from above (spindle M3), φ is measured clockwise from +Y, the
// element sits at (R·sin φ, R·cos φ). Forces are those acting on the tool:
//   Fx = −Ft·cos φ − Fr·sin φ,   Fy = Ft·sin φ − Fr·cos φ,   Fz = Fa.
// Up milling enters at φ = 0 (the finished wall is at +Y), down milling leaves at φ = π
// (the wall is at −Y); a slot is engaged over [0, π].
//
// Two force laws:
//  * linear edge-force model (Altintas): dFt = (K_tc·h + K_te)·dz, dFr = (K_rc·h + K_re)·dz,
//    dFa = (K_ac·h + K_ae)·dz — the digest's Al7075-T6 reference numbers use it;
//  * the paper's chip-thickness law: dFt = K_T(h)·dz·h, dFr = K_R(h)·dFt, with
//    K_T, K_R fitted to the instantaneous chip thickness (eq. 7, 12, 17). The paper
//    calls the fit "exponential"; its eq. 17 as OCR'd ("Kt=373.350)°e”",
//    "KR=0.3049"」26") reads best as power laws in t: K = c·t^e. Both forms are offered.
// Lengths mm, angles rad, forces N.
#include <Eigen/Core>
#include <string>
#include <vector>

namespace cnc::process {

enum class ForceModel { kLinearEdge, kChipThicknessLaw };
const char* to_string(ForceModel m);

struct LinearEdgeCoefficients {
  double ktc = 0, krc = 0, kac = 0;  // cutting coefficients, N/mm²
  double kte = 0, kre = 0, kae = 0;  // edge coefficients, N/mm
};

// K(t) = c·t^exponent (power) or c·exp(exponent·t) (exponential); t in mm.
struct CoefficientLaw {
  enum class Form { kPower, kExponential };
  Form form = Form::kPower;
  double c = 0;
  double exponent = 0;
  double operator()(double t) const;
};

struct ChipThicknessLaw {
  CoefficientLaw kt;  // K_T, N/mm²
  CoefficientLaw kr;  // K_R = dFr/dFt, dimensionless
  double ka = 0;      // dFa = ka·dFt (the paper is planar: 0)
  // The laws are evaluated at max(h, t_floor_mm): a power law with a negative exponent
  // diverges at h = 0, while the force K_T(h)·h still goes to 0.
  double t_floor_mm = 1e-4;
};

struct Material {
  std::string name;
  ForceModel model = ForceModel::kLinearEdge;  // the file's default law
  bool has_linear = false;
  LinearEdgeCoefficients linear;
  bool has_chip_law = false;
  ChipThicknessLaw chip_law;
  std::string validate(ForceModel m) const;  // "" when the law m is usable
};

struct EndMill {
  std::string name;
  std::string type = "flat";  // flat | ball
  int flutes = 4;
  double diameter_mm = 6.0;
  double helix_deg = 30.0;
  double overhang_mm = 25.0;                 // stick-out, holder to tip (cantilever length)
  double youngs_modulus_n_mm2 = 210000.0;    // HSS
  double effective_diameter_ratio = 0.8;     // Kops: D_e = 0.8·D for a 4-flute end mill (eq. 14)
  double radius() const { return 0.5 * diameter_mm; }
  std::string validate() const;
};

// The engaged arc [phi_start, phi_exit] (immersion angles, see above), axial depth
// and feed per tooth of a straight cut.
struct Engagement {
  double phi_start = 0;
  double phi_exit = 0;
  double axial_depth_mm = 0;
  double feed_per_tooth_mm = 0;
  static Engagement slot(double axial_depth, double feed_per_tooth);
  // Radial depth ae (0 < ae <= D): up milling [0, acos(1 − 2ae/D)], down milling
  // [π − acos(1 − 2ae/D), π].
  static Engagement up_milling(double diameter, double radial_depth, double axial_depth, double feed_per_tooth);
  static Engagement down_milling(double diameter, double radial_depth, double axial_depth, double feed_per_tooth);
};

struct ElementForce {
  double ft = 0, fr = 0, fa = 0;
};

// One element's tangential, radial, axial force for chip thickness h and height dz.
ElementForce element_force(const Material& mat, ForceModel model, double h, double dz);

// Projection (eq. 5) onto the tool's X, Y, Z.
Eigen::Vector3d project(const ElementForce& f, double phi);

struct ForceHistory {
  std::vector<double> theta;           // rotation angle of flute 0's bottom, rad
  std::vector<Eigen::Vector3d> force;  // on the tool, N
  Eigen::Vector3d mean() const;
};

class CuttingForceModel {
 public:
  // discs >= 1: the axial depth of each engagement is cut into that many discs.
  CuttingForceModel(EndMill tool, Material material, ForceModel model, int discs);

  const EndMill& tool() const { return tool_; }
  const Material& material() const { return material_; }
  ForceModel model() const { return model_; }
  int discs() const { return discs_; }
  double disc_height(const Engagement& e) const { return e.axial_depth_mm / discs_; }
  // The angle by which disc i+1 lags disc i: Dz·tan(h)/R.
  double lag_per_disc(const Engagement& e) const;

  // Total force on the tool at rotation angle theta.
  Eigen::Vector3d force(const Engagement& e, double theta) const;
  // Per-disc force (disc i's centre is (i + 1/2)·Dz above the tip); out has discs() entries.
  void disc_forces(const Engagement& e, double theta, std::vector<Eigen::Vector3d>& out) const;

  // The paper's angular step (eq. 11): the rotation per step equals the lag between
  // discs, Δθ = Dz·tan(h)/R, rounded so that a revolution has a whole multiple of N
  // steps; 90·N steps for a straight flute (no lag to tie the step to).
  int paper_steps_per_rev(const Engagement& e) const;
  // One revolution sampled at `steps` equal angles θ_j = j·2π/steps.
  ForceHistory simulate_revolution(const Engagement& e, int steps) const;

 private:
  EndMill tool_;
  Material material_;
  ForceModel model_;
  int discs_;
};

// Closed-form per-revolution mean force of a full slot under the linear edge-force
// model (Altintas): F̄x = −N·a·c·K_rc/4 − N·a·K_re/π, F̄y = N·a·c·K_tc/4 + N·a·K_te/π,
// F̄z = N·a·c·K_ac/π + N·a·K_ae/2.
Eigen::Vector3d slot_mean_force_closed_form(const LinearEdgeCoefficients& k, int flutes, double axial_depth,
                                            double feed_per_tooth);

}  // namespace cnc::process
