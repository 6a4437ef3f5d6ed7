#pragma once
// Small fixed-size vector and matrix types for host-side geometry. Templated on the
// scalar so the double-precision reference and float paths share one definition.

#include <array>
#include <cmath>
#include <cstdint>

namespace volcast {

template <typename T>
struct Vec3 {
    T x{}, y{}, z{};

    constexpr Vec3() = default;
    constexpr Vec3(T x_, T y_, T z_) : x(x_), y(y_), z(z_) {}
    template <typename U>
    constexpr explicit Vec3(const Vec3<U> &v) : x(T(v.x)), y(T(v.y)), z(T(v.z)) {}

    constexpr T operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
    constexpr T &operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }

    constexpr Vec3 operator+(const Vec3 &o) const { return {x + o.x, y + o.y, z + o.z}; }
    constexpr Vec3 operator-(const Vec3 &o) const { return {x - o.x, y - o.y, z - o.z}; }
    constexpr Vec3 operator-() const { return {-x, -y, -z}; }
    constexpr Vec3 operator*(T s) const { return {x * s, y * s, z * s}; }
    constexpr Vec3 operator/(T s) const { return {x / s, y / s, z / s}; }
    constexpr Vec3 &operator+=(const Vec3 &o) { x += o.x; y += o.y; z += o.z; return *this; }
    constexpr bool operator==(const Vec3 &) const = default;
};

template <typename T>
constexpr Vec3<T> operator*(T s, const Vec3<T> &v) { return v * s; }
template <typename T>
constexpr Vec3<T> mul(const Vec3<T> &a, const Vec3<T> &b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
template <typename T>
constexpr Vec3<T> div(const Vec3<T> &a, const Vec3<T> &b) { return {a.x / b.x, a.y / b.y, a.z / b.z}; }
template <typename T>
constexpr T dot(const Vec3<T> &a, const Vec3<T> &b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <typename T>
constexpr Vec3<T> cross(const Vec3<T> &a, const Vec3<T> &b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <typename T>
T length(const Vec3<T> &v) { return std::sqrt(dot(v, v)); }
template <typename T>
Vec3<T> normalize(const Vec3<T> &v) { return v / length(v); }
template <typename T>
constexpr T minComponent(const Vec3<T> &v) { return v.x < v.y ? (v.x < v.z ? v.x : v.z) : (v.y < v.z ? v.y : v.z); }

using Vec3d = Vec3<double>;
using Vec3f = Vec3<float>;
using Vec3i = Vec3<int64_t>;

// Row-major 3x3 matrix; columns of a direction matrix are the index axes in world space.
struct Mat3d {
    std::array<double, 9> m{1, 0, 0, 0, 1, 0, 0, 0, 1};

    static Mat3d identity() { return {}; }
    double operator()(int r, int c) const { return m[size_t(r * 3 + c)]; }
    double &operator()(int r, int c) { return m[size_t(r * 3 + c)]; }
    Vec3d operator*(const Vec3d &v) const {
        return {m[0] * v.x + m[1] * v.y + m[2] * v.z, m[3] * v.x + m[4] * v.y + m[5] * v.z,
                m[6] * v.x + m[7] * v.y + m[8] * v.z};
    }
    Mat3d transposed() const {
        Mat3d t;
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) t(r, c) = (*this)(c, r);
        return t;
    }
    bool operator==(const Mat3d &) const = default;
};

} // namespace volcast
