/* The EGL and GL headers of the kit's programs: OpenGL 3.3 core, or OpenGL ES 3.0 with
 * -DWXSKY_GL_ES (the GLES build of the library and its programs). */
#ifndef WXSKY_APPS_GL_API_H
#define WXSKY_APPS_GL_API_H

#include <EGL/egl.h>
#include <EGL/eglext.h>
#ifdef WXSKY_GL_ES
/* -DWXSKY_GL_ES: an OpenGL ES 3.0 context, for the GLES build of the library */
#include <GLES3/gl3.h>
#define WXSKY_EGL_API EGL_OPENGL_ES_API
#define WXSKY_EGL_BIT EGL_OPENGL_ES3_BIT
#define clear_depth(d) glClearDepthf((GLfloat)(d))
#else
#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#define WXSKY_EGL_API EGL_OPENGL_API
#define WXSKY_EGL_BIT EGL_OPENGL_BIT
#define clear_depth(d) glClearDepth(d)
#endif

#endif
