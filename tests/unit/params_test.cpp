#include <deform/sdk/params.h>
#include <deform/sdk/registry.h>
#include <gtest/gtest.h>

#include <stdexcept>

namespace deform {
namespace {

// Programmer errors assert in debug builds and throw std::logic_error in release builds.
#ifdef NDEBUG
#define EXPECT_PROGRAMMER_ERROR(stmt) EXPECT_THROW(stmt, std::logic_error)
#else
#define EXPECT_PROGRAMMER_ERROR(stmt) EXPECT_DEATH(stmt, "")
#endif

std::vector<ParamSpec> specs() {
  return {ParamSpec::integer("iterations", 10, 1, 1000, "solver iterations"),
          ParamSpec::real("stiffness", "1", 1.0, 0.0, 1.0, "constraint stiffness"),
          ParamSpec::flag("volume", true, "keep volume"),
          ParamSpec::choice("solver", "gauss_seidel", {"gauss_seidel", "jacobi"}, "solver")};
}

enum class Solver { GaussSeidel, Jacobi };
const std::vector<std::pair<std::string, Solver>> kSolvers = {{"gauss_seidel", Solver::GaussSeidel},
                                                              {"jacobi", Solver::Jacobi}};

TEST(Params, DefaultsHoldEveryDeclaredKeyWithItsType) {
  const ParamValues v = ParamValues::defaults(specs());
  EXPECT_EQ(v.all().size(), 4u);
  EXPECT_EQ(v.integer("iterations"), 10);
  EXPECT_EQ(v.real("stiffness"), 1.0);
  EXPECT_TRUE(v.flag("volume"));
  EXPECT_EQ(v.choice("solver"), "gauss_seidel");
  EXPECT_EQ(v.choiceAs("solver", kSolvers), Solver::GaussSeidel);
}

TEST(Params, SetValuesAreReadBack) {
  ParamValues v = ParamValues::defaults(specs());
  v.set("iterations", 20LL);
  v.set("stiffness", 0.25);
  v.set("volume", false);
  v.set("solver", std::string("jacobi"));
  EXPECT_EQ(v.integer("iterations"), 20);
  EXPECT_EQ(v.real("stiffness"), 0.25);
  EXPECT_FALSE(v.flag("volume"));
  EXPECT_EQ(v.choiceAs("solver", kSolvers), Solver::Jacobi);
}

TEST(Params, WrongTypeIsAProgrammerError) {
  const ParamValues v = ParamValues::defaults(specs());
  EXPECT_PROGRAMMER_ERROR(v.real("iterations"));
  EXPECT_PROGRAMMER_ERROR(v.integer("stiffness"));
  EXPECT_PROGRAMMER_ERROR(v.flag("solver"));
  EXPECT_PROGRAMMER_ERROR(v.choice("volume"));
}

TEST(Params, UndeclaredKeyIsAProgrammerError) {
  const ParamValues v = ParamValues::defaults(specs());
  EXPECT_PROGRAMMER_ERROR(v.real("young"));
  EXPECT_PROGRAMMER_ERROR(v.choice(""));
}

TEST(Params, ChoiceOutsideTheTableThrowsInputError) {
  ParamValues v = ParamValues::defaults(specs());
  v.set("solver", std::string("multigrid"));
  try {
    (void)v.choiceAs("solver", kSolvers);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("multigrid"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("solver"), std::string::npos) << e.what();
  }
}

TEST(Params, FormatNonDefaultListsChangedValuesInDeclarationOrder) {
  const auto s = specs();
  ParamValues v = ParamValues::defaults(s);
  EXPECT_EQ(formatNonDefault(v, s), "");
  // Set in the reverse of declaration order (and map order): output must follow declarations.
  v.set("stiffness", 0.5);
  v.set("iterations", 20LL);
  EXPECT_EQ(formatNonDefault(v, s), "iterations=20,stiffness=0.5");
  v.set("solver", std::string("jacobi"));
  v.set("volume", false);
  EXPECT_EQ(formatNonDefault(v, s), "iterations=20,stiffness=0.5,volume=false,solver=jacobi");
  v.set("iterations", 10LL);  // back to its default
  EXPECT_EQ(formatNonDefault(v, s), "stiffness=0.5,volume=false,solver=jacobi");
}

TEST(Params, FormatNonDefaultUsesShortestGeneralFormForReals) {
  const std::vector<ParamSpec> s = {ParamSpec::real("young", "Pa", 5500, 1, 1e12, "E")};
  ParamValues v = ParamValues::defaults(s);
  v.set("young", 1e9);
  EXPECT_EQ(formatNonDefault(v, s), "young=1e+09");
  v.set("young", 0.000125);
  EXPECT_EQ(formatNonDefault(v, s), "young=0.000125");
  v.set("young", 12345.678);
  EXPECT_EQ(formatNonDefault(v, s), "young=12345.7");
}

TEST(Registry, FindsModelsAndRejectsBadDeclarations) {
  auto make = [](std::string name, std::vector<ParamSpec> params) {
    ModelInfo m;
    m.name = std::move(name);
    m.params = std::move(params);
    m.capabilities = {Capability::Grasp, Capability::PointForce};
    m.create = [] { return std::unique_ptr<Model>(); };
    return m;
  };
  Registry r;
  r.add(make("a", specs()));
  ASSERT_NE(r.find("a"), nullptr);
  EXPECT_EQ(r.find("b"), nullptr);
  EXPECT_TRUE(r.find("a")->has(Capability::PointForce));
  EXPECT_FALSE(r.find("a")->has(Capability::Cut));
  ASSERT_NE(r.find("a")->param("stiffness"), nullptr);
  EXPECT_EQ(r.find("a")->param("stiffness")->type, ParamType::Real);
  EXPECT_EQ(r.find("a")->param("nope"), nullptr);

  // Defaults outside their range, choices without the default, repeated keys, no factory.
  EXPECT_THROW(r.add(make("c", {ParamSpec::real("k", "1", 2.0, 0.0, 1.0, "")})), std::logic_error);
  EXPECT_THROW(r.add(make("c", {ParamSpec::integer("n", 0, 1, 5, "")})), std::logic_error);
  EXPECT_THROW(r.add(make("c", {ParamSpec::choice("m", "x", {"a", "b"}, "")})), std::logic_error);
  EXPECT_THROW(r.add(make("c", {ParamSpec::flag("f", true, ""), ParamSpec::flag("f", false, "")})),
               std::logic_error);
  ModelInfo noFactory = make("c", {});
  noFactory.create = nullptr;
  EXPECT_THROW(r.add(std::move(noFactory)), std::logic_error);
  EXPECT_EQ(r.models().size(), 1u);
  EXPECT_PROGRAMMER_ERROR(r.add(make("a", {})));
}

TEST(Registry, CapabilityNamesAreTheSceneSpellings) {
  EXPECT_STREQ(capabilityName(Capability::Grasp), "grasp");
  EXPECT_STREQ(capabilityName(Capability::PointForce), "point_force");
  EXPECT_STREQ(capabilityName(Capability::Gravity), "gravity");
  EXPECT_STREQ(capabilityName(Capability::Cut), "cut");
  EXPECT_STREQ(capabilityName(Capability::ReactionForce), "reaction_force");
  EXPECT_STREQ(capabilityName(Capability::NeedsPrecompute), "needs_precompute");
  EXPECT_STREQ(capabilityName(Capability::TetInput), "tet_input");
  EXPECT_STREQ(capabilityName(Capability::QuasiStatic), "quasi_static");
}

}  // namespace
}  // namespace deform
