/* Gradient Phong shading (quality.shading) with a headlight: the constants the ray-casting
 * kernel (kernels/raycast.cl) and the reference integrator (shading.hpp) share. Plain
 * preprocessor values in C that OpenCL C and C++ both read, so that the reference and the
 * model need no OpenCL header to agree with the kernel. The build embeds this file before
 * the kernel's source. */
#ifndef VOLCAST_PHONG_CONSTANTS_H
#define VOLCAST_PHONG_CONSTANTS_H

#define VC_PHONG_AMBIENT 0.3f
#define VC_PHONG_DIFFUSE 0.7f
#define VC_PHONG_SPECULAR 0.2f
#define VC_PHONG_SHININESS 20.0f

#endif
