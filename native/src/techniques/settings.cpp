#include "techniques/settings.h"

#include <cassert>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>

namespace px {

namespace {

std::string number_text(double v) {
    char text[32];
    std::snprintf(text, sizeof(text), "%.10g", v);
    return text;
}

std::string item_names(const SettingInfo& row) {
    std::string names;
    for (const EnumItem& i : row.items) names += std::string(names.empty() ? "" : ", ") + i.name;
    return names;
}

[[noreturn]] void fail(const SettingInfo& row, const std::string& what, const std::string& got) {
    throw std::invalid_argument(std::string(row.name) + " must be " + what + ", got " + got);
}

std::string range_text(const SettingInfo& row) {
    return "in [" + number_text(row.min) + ", " + number_text(row.max) + "]";
}

void store(void* block, const SettingInfo& row, double v) {
    char* p = static_cast<char*>(block) + row.field.offset;
    switch (row.field.storage) {
    case Storage::U32: {
        const uint32_t u = uint32_t(v);
        std::memcpy(p, &u, 4);
        break;
    }
    case Storage::I32: {
        const int32_t i = int32_t(v);
        std::memcpy(p, &i, 4);
        break;
    }
    case Storage::F32: {
        const float f = float(v);
        std::memcpy(p, &f, 4);
        break;
    }
    case Storage::None:
        break;
    }
}

// The range check of a number the row's field can hold (NaN fails).
void check_number(const SettingInfo& row, double v, const std::string& got) {
    if (row.type == SettingType::Bool) {
        if (v != 0 && v != 1) fail(row, "0 or 1 (a boolean)", got);
    } else if (row.type == SettingType::Enum) {
        if (v != std::floor(v) || v < 0 || v > 4294967295.0 || !row.item(uint32_t(v)))
            fail(row, "one of " + item_names(row), got);
    } else if (row.field.storage == Storage::F32) {  // the ends as the field holds them
        const float f = float(v);
        if (!(f >= float(row.min) && f <= float(row.max))) fail(row, range_text(row), got);
    } else if (!(v >= row.min && v <= row.max)) {
        fail(row, range_text(row), got);
    }
}

SettingInfo row(const char* name, SettingType type, FieldRef field, double def, double min, double max,
                const char* label, const char* tooltip, const char* panel) {
    SettingInfo r{name, type, field, def, min, max, {}, label, tooltip, panel};
    return r;
}

}  // namespace

const EnumItem* SettingInfo::item(const std::string& n) const {
    for (const EnumItem& i : items)
        if (n == i.name) return &i;
    return nullptr;
}

const EnumItem* SettingInfo::item(uint32_t value) const {
    for (const EnumItem& i : items)
        if (i.value == value) return &i;
    return nullptr;
}

SettingInfo bool_setting(const char* name, FieldRef field, bool def, const char* label, const char* tooltip,
                         const char* panel) {
    assert(field.storage == Storage::U32 || field.storage == Storage::None);  // None: an engine setting
    return row(name, SettingType::Bool, field, def ? 1 : 0, 0, 1, label, tooltip, panel);
}

SettingInfo int_setting(const char* name, FieldRef field, int64_t def, int64_t min, int64_t max, const char* label,
                        const char* tooltip, const char* panel) {
    assert(min <= def && def <= max);
    assert(field.storage != Storage::F32);
    assert(field.storage != Storage::U32 || (min >= 0 && max <= int64_t(UINT32_MAX)));
    assert(field.storage != Storage::I32 || (min >= INT32_MIN && max <= INT32_MAX));
    return row(name, SettingType::Int, field, double(def), double(min), double(max), label, tooltip, panel);
}

SettingInfo float_setting(const char* name, FieldRef field, double def, double min, double max, const char* label,
                          const char* tooltip, const char* panel) {
    assert(min <= def && def <= max);
    assert(field.storage == Storage::F32 || field.storage == Storage::None);
    return row(name, SettingType::Float, field, def, min, max, label, tooltip, panel);
}

SettingInfo enum_setting(const char* name, FieldRef field, uint32_t def, std::vector<EnumItem> items,
                         const char* label, const char* tooltip, const char* panel) {
    assert(field.storage == Storage::U32 || field.storage == Storage::None);
    SettingInfo r = row(name, SettingType::Enum, field, def, 0, 0, label, tooltip, panel);
    r.items = std::move(items);
    assert(r.item(def));
    return r;
}

void write_setting(void* block, const SettingInfo& row, const SettingValue& value) {
    using K = SettingValue::Kind;
    double v = 0;
    switch (row.type) {
    case SettingType::Bool:  // a boolean, or the integers 0 and 1
        if (value.kind != K::Bool && value.kind != K::Int) fail(row, "a boolean", value.repr);
        v = value.number;
        break;
    case SettingType::Int:
        if (value.kind != K::Int && value.kind != K::Bool) fail(row, "an integer " + range_text(row), value.repr);
        v = value.number;
        break;
    case SettingType::Float:
        if (value.kind != K::Float && value.kind != K::Int) fail(row, "a number " + range_text(row), value.repr);
        v = value.number;
        break;
    case SettingType::Enum: {
        const EnumItem* item = value.kind == K::Text ? row.item(value.text) : nullptr;
        if (!item) fail(row, "one of " + item_names(row), value.repr);
        v = item->value;
        break;
    }
    }
    check_number(row, v, value.repr);
    store(block, row, v);
}

double read_setting(const void* block, const SettingInfo& row) {
    const char* p = static_cast<const char*>(block) + row.field.offset;
    switch (row.field.storage) {
    case Storage::U32: {
        uint32_t u;
        std::memcpy(&u, p, 4);
        return u;
    }
    case Storage::I32: {
        int32_t i;
        std::memcpy(&i, p, 4);
        return i;
    }
    case Storage::F32: {
        float f;
        std::memcpy(&f, p, 4);
        return f;
    }
    case Storage::None:
        break;
    }
    return row.default_value;
}

void write_defaults(void* block, const std::vector<SettingInfo>& rows) {
    for (const SettingInfo& r : rows) store(block, r, r.default_value);
}

void check_settings(const void* block, const std::vector<SettingInfo>& rows) {
    for (const SettingInfo& r : rows)
        if (r.core()) {
            const double v = read_setting(block, r);
            check_number(r, v, number_text(v));
        }
}

}  // namespace px
