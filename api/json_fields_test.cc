#include "api/json_fields.h"

#include <functional>

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

// The whole message, word for word: clients read it in a 400.
std::string Refusal(const std::function<void()>& read) {
  try {
    read();
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "accepted";
}

TEST(JsonFields, MessagesNameTheFieldByItsPath) {
  const json params = {{"n", "x"}, {"i", 1.5}, {"b", 1}};
  EXPECT_EQ(Refusal([&] { NumberField(params, "params", "n"); }),
            "field 'params.n' must be a number");
  EXPECT_EQ(Refusal([&] { IntegerField(params, "params", "i"); }),
            "field 'params.i' must be an integer");
  EXPECT_EQ(Refusal([&] { BoolField(params, "options", "b"); }),
            "field 'options.b' must be true or false");
  EXPECT_EQ(Refusal([&] { NumberField(params, "board", "gone"); }), "missing field 'board.gone'");
  EXPECT_EQ(Refusal([&] { CheckKnownFields(params, "params", {"n", "i"}); }),
            "unknown field 'params.b'");
  EXPECT_EQ(Refusal([&] { CheckKnownFields(json::array(), "options", {}); }),
            "'options' must be a JSON object");
  EXPECT_EQ(Refusal([&] { StringField(params, "", "i"); }), "field 'i' must be a string");
  EXPECT_EQ(Refusal([&] {
              JobIdField({{"rig", ""}}, "params", "rig");
            }),
            "field 'params.rig' must be a job id (a non-empty string)");
  EXPECT_EQ(Refusal([&] { CheckKnownFields(params, "", {"n", "i"}); }), "unknown field 'b'");
}

TEST(JsonFields, IntegersMustFitAnInt) {
  EXPECT_EQ(IntegerField({{"i", -2147483648LL}}, "params", "i"), -2147483648LL);
  for (const json& big : {json(2147483648LL), json(-2147483649LL), json(18446744073709551615ULL)}) {
    EXPECT_EQ(Refusal([&] {
                IntegerField({{"i", big}}, "params", "i");
              }),
              "field 'params.i' is out of range");
  }
}

TEST(JsonFields, ErrorPrefixNamesTheFieldAndKeepsTheValue) {
  EXPECT_EQ(WithErrorPrefix("field 'board': ", [] { return 3; }), 3);
  EXPECT_EQ(Refusal([] {
              WithErrorPrefix("field 'board': ",
                              [] { throw InvalidArgument("cols must be >= 2"); });
            }),
            "field 'board': cols must be >= 2");
}

TEST(JsonFields, NumberVectorsHaveTheirSize) {
  EXPECT_EQ(NumberVector<2>(json{1.5, 2}, "options.p"), Eigen::Vector2d(1.5, 2));
  EXPECT_EQ(Refusal([&] {
              NumberVector<3>(json{1, 2}, "options.p");
            }),
            "field 'options.p' must be an array of 3 numbers");
  EXPECT_EQ(Refusal([&] {
              NumberVector<2>(json{1, "2"}, "options.p");
            }),
            "field 'options.p' must hold numbers only");
}

TEST(JsonFields, OptionalFormsKeepTheDefaultWhenAbsent) {
  double number = 2.5;
  int integer = 7;
  bool flag = true;
  ReadNumber(json::object(), "params", "x", &number);
  ReadInteger(json::object(), "params", "x", &integer);
  ReadBool(json::object(), "params", "x", &flag);
  EXPECT_EQ(number, 2.5);
  EXPECT_EQ(integer, 7);
  EXPECT_TRUE(flag);
  ReadNumber({{"x", 3}}, "params", "x", &number);
  EXPECT_EQ(number, 3.0);
}

TEST(JsonFields, OptionTableReadsAndEchoesEachFieldWithItsType) {
  struct Options {
    double step = 0.5;
    int size = 3;
    bool check = false;
  } options;
  const OptionTable table = {
      {"step", &options.step}, {"size", &options.size}, {"check", &options.check}};
  EXPECT_EQ(KeysOf(table), (std::set<std::string>{"check", "size", "step"}));
  ReadOptions({{"size", 5}, {"check", true}}, "params", table);
  EXPECT_EQ(options.step, 0.5);
  EXPECT_EQ(options.size, 5);
  EXPECT_TRUE(options.check);
  const json echo = OptionsToJson(table);
  EXPECT_TRUE(echo["step"].is_number_float());
  EXPECT_TRUE(echo["size"].is_number_integer());
  EXPECT_TRUE(echo["check"].is_boolean());
  EXPECT_EQ(Refusal([&] { ReadOptions({{"size", 1.5}}, "params", table); }),
            "field 'params.size' must be an integer");
}

}  // namespace
}  // namespace omnirig::api
