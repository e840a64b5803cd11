#include <gtest/gtest.h>

#include "codecs/codec.h"
#include "core/params.h"

using namespace btfc;

static const ParamSpec k_table[] = {
    {"rank", ParamSpec::Type::integer, "32", 1, 4096, {}, "components"},
    {"tol", ParamSpec::Type::real, "0.5", 0, 1, {}, "tolerance"},
    {"precision", ParamSpec::Type::choice, "half", 0, 0, {"half", "float"}, "storage"},
};

TEST(Params, DefaultsAndCanonicalOrder) {
  auto s = parse_spec_string("x:precision=float");
  ASSERT_TRUE(s.ok());
  auto p = bind_params(s.value(), k_table);
  ASSERT_TRUE(p.ok()) << p.status().message();
  EXPECT_EQ(p->get_int("rank"), 32);
  EXPECT_DOUBLE_EQ(p->get_real("tol"), 0.5);
  EXPECT_EQ(p->get("precision"), "float");
  EXPECT_TRUE(p->was_set("precision"));
  EXPECT_FALSE(p->was_set("rank"));
  EXPECT_EQ(p->canonical(), "x:rank=32:tol=0.5:precision=float");
}

TEST(Params, CanonicalRoundTrips) {
  auto p = bind_params(parse_spec_string("x:rank=07:tol=0.25").value(), k_table).value();
  auto q = bind_params(parse_spec_string(p.canonical()).value(), k_table).value();
  EXPECT_EQ(p.canonical(), q.canonical());
  EXPECT_EQ(q.get_int("rank"), 7);
}

TEST(Params, Errors) {
  auto bind = [](const char* text) { return bind_params(parse_spec_string(text).value(), k_table).status(); };
  Status s = bind("x:rnak=3");
  EXPECT_EQ(s.code(), StatusCode::invalid_argument);
  EXPECT_NE(s.message().find("unknown parameter 'rnak'"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("rank"), std::string::npos);  // lists the known ones
  EXPECT_NE(bind("x:rank=0").message().find("outside [1, 4096]"), std::string::npos);
  EXPECT_NE(bind("x:rank=5000").message().find("outside"), std::string::npos);
  EXPECT_NE(bind("x:rank=3.5").message().find("not an integer"), std::string::npos);
  EXPECT_NE(bind("x:tol=abc").message().find("not a number"), std::string::npos);
  EXPECT_NE(bind("x:tol=nan").message().find("not a number"), std::string::npos);
  EXPECT_NE(bind("x:precision=double").message().find("half|float"), std::string::npos);
  EXPECT_FALSE(parse_spec_string("x:rank").ok());
  EXPECT_FALSE(parse_spec_string("x:=3").ok());
  EXPECT_FALSE(parse_spec_string(":rank=3").ok());
  EXPECT_FALSE(parse_spec_string("x:rank=1:rank=2").ok());
}

TEST(Registry, ResolvesCodecs) {
  ASSERT_FALSE(all_codecs().empty());
  auto r = resolve_spec("fmf:rank=8");
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_STREQ(r->first->name(), "fmf");
  EXPECT_EQ(r->second.get_int("rank"), 8);
  Status s = resolve_spec("nosuch:rank=8").status();
  EXPECT_NE(s.message().find("unknown codec 'nosuch'"), std::string::npos);
  EXPECT_NE(s.message().find("fmf"), std::string::npos);
  EXPECT_FALSE(resolve_spec("fmf:bogus=1").ok());
}
