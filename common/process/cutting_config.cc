#include "common/process/cutting_config.h"

#include <stdexcept>

#include "common/config/yaml_reader.h"

namespace cnc::process {
namespace {
using cnc::config::MapReader;

CoefficientLaw read_law(MapReader r) {
  CoefficientLaw law;
  law.form = r.get_choice("form", "power", {"power", "exponential"}) == "power" ? CoefficientLaw::Form::kPower
                                                                                : CoefficientLaw::Form::kExponential;
  law.c = r.require_double("c", 0.0);
  law.exponent = r.get_double("exponent", 0.0, -10.0, 10.0);
  r.finish();
  return law;
}
}  // namespace

ForceModel force_model_from_string(const std::string& s) {
  if (s == "linear_edge" || s == "linear") return ForceModel::kLinearEdge;
  if (s == "chip_thickness_law" || s == "chip") return ForceModel::kChipThicknessLaw;
  throw std::invalid_argument("force model '" + s + "' is not one of: linear_edge, chip_thickness_law");
}

Material load_material(const std::string& file) {
  MapReader r(cnc::config::load_yaml_file(file), "", file);
  Material m;
  m.name = r.require_string("name");
  r.get_string("source", "");  // free text: where the numbers come from
  m.model = force_model_from_string(r.get_choice("model", "linear_edge", {"linear_edge", "chip_thickness_law"}));
  if (r.has("linear_edge")) {
    MapReader l = r.map("linear_edge");
    m.has_linear = true;
    m.linear.ktc = l.require_double("ktc_n_mm2");
    m.linear.krc = l.require_double("krc_n_mm2");
    m.linear.kac = l.get_double("kac_n_mm2", 0.0);
    m.linear.kte = l.get_double("kte_n_mm", 0.0);
    m.linear.kre = l.get_double("kre_n_mm", 0.0);
    m.linear.kae = l.get_double("kae_n_mm", 0.0);
    l.finish();
  }
  if (r.has("chip_thickness_law")) {
    MapReader c = r.map("chip_thickness_law");
    m.has_chip_law = true;
    m.chip_law.kt = read_law(c.map("kt_n_mm2"));
    m.chip_law.kr = read_law(c.map("kr"));
    m.chip_law.ka = c.get_double("ka", 0.0);
    m.chip_law.t_floor_mm = c.get_double("t_floor_mm", 1e-4, 1e-9, 1.0);
    c.finish();
  }
  r.finish();
  const std::string err = m.validate(m.model);
  if (!err.empty()) throw cnc::config::ConfigError(file, "model", err);
  return m;
}

EndMill load_tool(const std::string& file) {
  MapReader r(cnc::config::load_yaml_file(file), "", file);
  EndMill t;
  t.name = r.require_string("name");
  r.get_string("source", "");
  t.type = r.get_choice("type", "flat", {"flat", "ball"});
  t.flutes = static_cast<int>(r.require_int("flutes", 1, 64));
  t.diameter_mm = r.require_double("diameter_mm", 1e-3, 1e4);
  t.helix_deg = r.get_double("helix_deg", 30.0, 0.0, 79.0);
  t.overhang_mm = r.get_double("overhang_mm", 4.0 * t.diameter_mm, 1e-3, 1e4);
  t.youngs_modulus_n_mm2 = r.get_double("youngs_modulus_n_mm2", 210000.0, 1.0, 1e7);
  t.effective_diameter_ratio = r.get_double("effective_diameter_ratio", 0.8, 0.01, 1.0);
  r.finish();
  const std::string err = t.validate();
  if (!err.empty()) throw cnc::config::ConfigError(file, "", err);
  return t;
}

}  // namespace cnc::process
