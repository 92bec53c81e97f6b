// Recording stand-ins for the Geant4 classes that Geant4's old solid unit tests (testG4*.cc)
// use: solids write their parameters as JSON lines, ray queries (DistanceToIn(p, v),
// DistanceToOut(p, v), Inside(p)) their solid, point and direction, to the file named by
// MOCK_OUT. Queries answer 0 and assertions only evaluate their argument, so a test runs
// through; see extract.py.
#pragma once
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>
#include <iostream>
#include <iomanip>
#include <fstream>
#include <sstream>
#include <limits>
#include <cfloat>
#undef assert
#define assert(x) ((void)(x))
typedef double G4double; typedef int G4int; typedef bool G4bool; typedef std::string G4String;
typedef long G4long; typedef float G4float;
#define G4cout std::cout
#define G4cerr std::cerr
#define G4endl std::endl
#define G4ios std::ios
namespace std_dummy{}
static const double pi = 3.14159265358979323846, twopi = 2*pi, halfpi = pi/2;
static const double mm = 1, cm = 10, m = 1000, km = 1e6, um = 1e-3, micrometer=1e-3, nm = 1e-6, millimeter=1, centimeter=10, meter=1000;
static const double rad = 1, radian = 1, deg = pi/180, degree = pi/180, mrad = 1e-3;
static const double perCent = 0.01, perMillion = 1e-6;
static const double kInfinity = 9.0e99;
static const double kCarTolerance_g = 1e-9;
enum EInside { kOutside, kSurface, kInside };
enum EAxis { kXAxis, kYAxis, kZAxis, kRho, kRadial3D, kPhi, kUndefined };
enum ESide { kUndef };
inline bool ApproxEqual(double a, double b) { return std::fabs(a-b) < 1e-10 || (b!=0 && std::fabs(a/b-1)<1e-10); }
struct G4ThreeVector {
  double dx, dy, dz;
  G4ThreeVector(double a=0, double b=0, double c=0): dx(a), dy(b), dz(c) {}
  template<class V, class = decltype(&V::setX), class = decltype(std::declval<V>().dx)> G4ThreeVector(const V& v, int* =0): dx(v.dx), dy(v.dy), dz(0) {}
  double x() const {return dx;} double y() const {return dy;} double z() const {return dz;}
  double getX() const {return dx;} double getY() const {return dy;} double getZ() const {return dz;}
  void setX(double a){dx=a;} void setY(double a){dy=a;} void setZ(double a){dz=a;}
  void set(double a,double b,double c){dx=a;dy=b;dz=c;}
  double mag2() const {return dx*dx+dy*dy+dz*dz;} double mag() const {return std::sqrt(mag2());}
  double perp2() const {return dx*dx+dy*dy;} double perp() const {return std::sqrt(perp2());}
  double phi() const {return (dx==0&&dy==0)?0:std::atan2(dy,dx);} double theta() const {return (dx==0&&dy==0&&dz==0)?0:std::atan2(perp(),dz);}
  double r() const {return mag();}
  double cosTheta() const { double m=mag(); return m==0?1:dz/m; }
  G4ThreeVector unit() const {double m=mag(); return m>0?G4ThreeVector(dx/m,dy/m,dz/m):*this;}
  double dot(const G4ThreeVector&o) const {return dx*o.dx+dy*o.dy+dz*o.dz;}
  G4ThreeVector cross(const G4ThreeVector&o) const {return G4ThreeVector(dy*o.dz-dz*o.dy, dz*o.dx-dx*o.dz, dx*o.dy-dy*o.dx);}
  G4ThreeVector& operator+=(const G4ThreeVector&o){dx+=o.dx;dy+=o.dy;dz+=o.dz;return *this;}
  G4ThreeVector& operator-=(const G4ThreeVector&o){dx-=o.dx;dy-=o.dy;dz-=o.dz;return *this;}
  G4ThreeVector& operator*=(double a){dx*=a;dy*=a;dz*=a;return *this;}
  G4ThreeVector& operator/=(double a){dx/=a;dy/=a;dz/=a;return *this;}
  G4ThreeVector operator-() const {return G4ThreeVector(-dx,-dy,-dz);}
  double operator[](int i) const {return i==0?dx:i==1?dy:dz;}
  double operator()(int i) const {return (*this)[i];}
  bool operator==(const G4ThreeVector&o) const {return dx==o.dx&&dy==o.dy&&dz==o.dz;}
  bool operator!=(const G4ThreeVector&o) const {return !(*this==o);}
  G4ThreeVector& rotateX(double a){double c=std::cos(a),s=std::sin(a); double y=c*dy-s*dz, z=s*dy+c*dz; dy=y; dz=z; return *this;}
  G4ThreeVector& rotateY(double a){double c=std::cos(a),s=std::sin(a); double z=c*dz-s*dx, x=s*dz+c*dx; dz=z; dx=x; return *this;}
  G4ThreeVector& rotateZ(double a){double c=std::cos(a),s=std::sin(a); double x=c*dx-s*dy, y=s*dx+c*dy; dx=x; dy=y; return *this;}
  void setMag(double m){ *this = unit(); *this *= m; }
  void setRThetaPhi(double r,double t,double p){dx=r*std::sin(t)*std::cos(p);dy=r*std::sin(t)*std::sin(p);dz=r*std::cos(t);}
};
typedef G4ThreeVector G4Point3D; typedef G4ThreeVector G4Vector3D; typedef G4ThreeVector G4Normal3D;
inline bool ApproxEqual(const G4ThreeVector&a,const G4ThreeVector&b){return ApproxEqual(a.dx,b.dx)&&ApproxEqual(a.dy,b.dy)&&ApproxEqual(a.dz,b.dz);}
inline G4ThreeVector operator+(G4ThreeVector a,const G4ThreeVector&b){return a+=b;}
inline G4ThreeVector operator-(G4ThreeVector a,const G4ThreeVector&b){return a-=b;}
inline G4ThreeVector operator*(G4ThreeVector a,double s){return a*=s;}
inline G4ThreeVector operator*(double s,G4ThreeVector a){return a*=s;}
inline G4ThreeVector operator/(G4ThreeVector a,double s){return a/=s;}
inline double operator*(const G4ThreeVector&a,const G4ThreeVector&b){return a.dot(b);}
inline std::ostream& operator<<(std::ostream&o,const G4ThreeVector&v){return o<<"("<<v.dx<<","<<v.dy<<","<<v.dz<<")";}
struct G4TwoVector { double dx, dy; G4TwoVector(double a=0,double b=0):dx(a),dy(b){} double x() const{return dx;} double y() const{return dy;}
  void setX(double a){dx=a;} void setY(double a){dy=a;} void set(double a,double b){dx=a;dy=b;} };
inline G4TwoVector operator-(const G4TwoVector&a,const G4TwoVector&b){return G4TwoVector(a.dx-b.dx,a.dy-b.dy);}
inline G4TwoVector operator+(const G4TwoVector&a,const G4TwoVector&b){return G4TwoVector(a.dx+b.dx,a.dy+b.dy);}
inline G4TwoVector operator*(double s,const G4TwoVector&a){return G4TwoVector(s*a.dx,s*a.dy);}
inline std::ostream& operator<<(std::ostream&o,const G4TwoVector&v){return o<<"("<<v.dx<<","<<v.dy<<")";}
struct G4RotationMatrix {
  double m[3][3];
  G4RotationMatrix(){for(int i=0;i<3;i++)for(int j=0;j<3;j++)m[i][j]=i==j;}
  G4RotationMatrix& lmul(const double r[3][3]){double t[3][3];for(int i=0;i<3;i++)for(int j=0;j<3;j++){t[i][j]=0;for(int k=0;k<3;k++)t[i][j]+=r[i][k]*m[k][j];} for(int i=0;i<3;i++)for(int j=0;j<3;j++)m[i][j]=t[i][j]; return *this;}
  G4RotationMatrix& rotateX(double a){double c=std::cos(a),s=std::sin(a); double r[3][3]={{1,0,0},{0,c,-s},{0,s,c}}; return lmul(r);}
  G4RotationMatrix& rotateY(double a){double c=std::cos(a),s=std::sin(a); double r[3][3]={{c,0,s},{0,1,0},{-s,0,c}}; return lmul(r);}
  G4RotationMatrix& rotateZ(double a){double c=std::cos(a),s=std::sin(a); double r[3][3]={{c,-s,0},{s,c,0},{0,0,1}}; return lmul(r);}
  G4RotationMatrix inverse() const {G4RotationMatrix r; for(int i=0;i<3;i++)for(int j=0;j<3;j++)r.m[i][j]=m[j][i]; return r;}
  G4RotationMatrix& invert(){*this=inverse(); return *this;}
  G4ThreeVector operator*(const G4ThreeVector&v) const {return G4ThreeVector(m[0][0]*v.dx+m[0][1]*v.dy+m[0][2]*v.dz,m[1][0]*v.dx+m[1][1]*v.dy+m[1][2]*v.dz,m[2][0]*v.dx+m[2][1]*v.dy+m[2][2]*v.dz);}
};
struct G4Transform3D { G4RotationMatrix r; G4ThreeVector t; G4Transform3D(){} G4Transform3D(const G4RotationMatrix&a,const G4ThreeVector&b):r(a),t(b){}
  G4Transform3D operator*(const G4Transform3D&o) const { G4Transform3D x; for(int i=0;i<3;i++)for(int j=0;j<3;j++){x.r.m[i][j]=0;for(int k=0;k<3;k++)x.r.m[i][j]+=r.m[i][k]*o.r.m[k][j];} x.t=r*o.t+t; return x; } };
struct G4Translate3D: G4Transform3D { G4Translate3D(double a,double b,double c){t=G4ThreeVector(a,b,c);} G4Translate3D(const G4ThreeVector&v){t=v;} };
struct G4RotateX3D: G4Transform3D { G4RotateX3D(double a){r.rotateX(a);} };
struct G4RotateY3D: G4Transform3D { G4RotateY3D(double a){r.rotateY(a);} };
struct G4RotateZ3D: G4Transform3D { G4RotateZ3D(double a){r.rotateZ(a);} };
struct G4ReflectX3D: G4Transform3D { G4ReflectX3D(){r.m[0][0]=-1;} };
struct G4AffineTransform { G4AffineTransform(){} G4AffineTransform(const G4ThreeVector&){} G4AffineTransform(const G4RotationMatrix&,const G4ThreeVector&){} G4AffineTransform(const G4RotationMatrix*,const G4ThreeVector&){} };
struct G4VoxelLimits { void AddLimit(EAxis,double,double){} };
struct G4GeometryTolerance { static G4GeometryTolerance* GetInstance(){static G4GeometryTolerance g; return &g;} double GetSurfaceTolerance(){return 1e-9;} double GetAngularTolerance(){return 1e-9;} double GetRadialTolerance(){return 1e-9;} };
inline double G4UniformRand(){ return std::rand()/(RAND_MAX+1.0); }
struct G4Timer { void Start(){} void Stop(){} double GetUserElapsed(){return 0;} double GetRealElapsed(){return 0;} double GetSystemElapsed(){return 0;} };
inline std::ostream& operator<<(std::ostream&o,const G4Timer&){return o;}
inline void G4Exception(const char*,const char*,int,const char*){}
enum G4ExceptionSeverity { FatalException, JustWarning, FatalErrorInArgument };
struct G4Polyhedron {};
class G4VSolid;
// ----- recorder -----
struct Rec { static std::FILE* f(){ static std::FILE* fp = std::fopen(std::getenv("MOCK_OUT"), "w"); return fp; } static int& n(){static int k=0; return k;} static int& calls(){static int c=0; return c;} };
inline std::string num(double x){ char b[64]; std::snprintf(b,64,"%.17g",x); std::string s(b); if(s=="inf"||s=="nan"||s=="-inf") return "null"; return s; }
inline std::string vec(const G4ThreeVector&v){ return "["+num(v.dx)+","+num(v.dy)+","+num(v.dz)+"]"; }
struct G4SolidRecord {};
class G4VSolid {
 public:
  int id; std::string name;
  G4VSolid(const std::string&n, const std::string& spec): name(n) { id = Rec::n()++; std::fprintf(Rec::f(), "{\"solid\":%d,\"name\":\"%s\",\"spec\":%s}\n", id, n.c_str(), spec.c_str()); std::fflush(Rec::f()); }
  virtual ~G4VSolid(){}
  void ray(const char* q, const G4ThreeVector&p, const G4ThreeVector&v) const { if(++Rec::calls()>200000) std::exit(0); std::fprintf(Rec::f(), "{\"call\":\"%s\",\"solid\":%d,\"p\":%s,\"v\":%s}\n", q, id, vec(p).c_str(), vec(v).c_str()); }
  EInside Inside(const G4ThreeVector&p) const { ray("inside", p, G4ThreeVector()); return kInside; }
  G4ThreeVector SurfaceNormal(const G4ThreeVector&p) const { return G4ThreeVector(0,0,1); }
  double DistanceToIn(const G4ThreeVector&p) const { if(++Rec::calls()>200000) std::exit(0); return 0; }
  double DistanceToIn(const G4ThreeVector&p,const G4ThreeVector&v) const { ray("in",p,v); return 0; }
  double DistanceToOut(const G4ThreeVector&p) const { if(++Rec::calls()>200000) std::exit(0); return 0; }
  double DistanceToOut(const G4ThreeVector&p,const G4ThreeVector&v,bool calc=false,bool* valid=0,G4ThreeVector* n=0) const { ray("out",p,v); if(valid)*valid=true; if(n)*n=G4ThreeVector(0,0,1); return 0; }
  double GetCubicVolume(){return 0;} double GetSurfaceArea(){return 0;}
  G4String GetName() const {return name;} G4String GetEntityType() const {return "";}
  bool CalculateExtent(EAxis, const G4VoxelLimits&, const G4AffineTransform&, double&a, double&b) const {a=b=0; return false;}
  G4ThreeVector GetPointOnSurface() const { return G4ThreeVector(); }
  std::ostream& StreamInfo(std::ostream&o) const {return o;}
  G4Polyhedron* CreatePolyhedron() const {return 0;} G4Polyhedron* GetPolyhedron() const {return 0;}
  void BoundingLimits(G4ThreeVector&, G4ThreeVector&) const {}
};
inline std::string kv(const char*k,double v){return std::string("\"")+k+"\":"+num(v);}
inline std::string obj(const char*t,std::initializer_list<std::string> l){std::string s=std::string("{\"type\":\"")+t+"\""; for(auto&x:l) s+=","+x; return s+"}";}
inline std::string arr(int n,const double*a){std::string s="["; for(int i=0;i<n;i++){ if(i) s+=","; s+=num(a[i]);} return s+"]";}
// Accessors the tests call, answering 0.
#define ACC(n) double Get##n() const {return 0;}
struct G4Box: G4VSolid { G4Box(const G4String&n,double x,double y,double z):G4VSolid(n,obj("box",{kv("dx",x),kv("dy",y),kv("dz",z)})){} ACC(XHalfLength) ACC(YHalfLength) ACC(ZHalfLength) };
struct G4Orb: G4VSolid { G4Orb(const G4String&n,double r):G4VSolid(n,obj("orb",{kv("r",r)})){} ACC(Radius) };
struct G4Sphere: G4VSolid { G4Sphere(const G4String&n,double a,double b,double c,double d,double e,double f):G4VSolid(n,obj("sphere",{kv("rmin",a),kv("rmax",b),kv("sphi",c),kv("dphi",d),kv("stheta",e),kv("dtheta",f)})){} ACC(InsideRadius) ACC(OuterRadius) };
struct G4Tubs: G4VSolid { G4Tubs(const G4String&n,double a,double b,double c,double d,double e):G4VSolid(n,obj("tubs",{kv("rmin",a),kv("rmax",b),kv("dz",c),kv("sphi",d),kv("dphi",e)})){} ACC(InnerRadius) ACC(OuterRadius) ACC(ZHalfLength) ACC(StartPhiAngle) ACC(DeltaPhiAngle) };
struct G4Cons: G4VSolid { G4Cons(const G4String&n,double a,double b,double c,double d,double e,double f,double g):G4VSolid(n,obj("cons",{kv("rmin1",a),kv("rmax1",b),kv("rmin2",c),kv("rmax2",d),kv("dz",e),kv("sphi",f),kv("dphi",g)})){} };
struct G4Torus: G4VSolid { G4Torus(const G4String&n,double a,double b,double c,double d,double e):G4VSolid(n,obj("torus",{kv("rmin",a),kv("rmax",b),kv("rtor",c),kv("sphi",d),kv("dphi",e)})){} };
struct G4Trd: G4VSolid { G4Trd(const G4String&n,double a,double b,double c,double d,double e):G4VSolid(n,obj("trd",{kv("dx1",a),kv("dx2",b),kv("dy1",c),kv("dy2",d),kv("dz",e)})){} };
inline std::string trap_spec(double dz,double th,double ph,double dy1,double dx1,double dx2,double a1,double dy2,double dx3,double dx4,double a2){return obj("trap",{kv("dz",dz),kv("theta",th),kv("phi",ph),kv("dy1",dy1),kv("dx1",dx1),kv("dx2",dx2),kv("alpha1",a1),kv("dy2",dy2),kv("dx3",dx3),kv("dx4",dx4),kv("alpha2",a2)});}
inline std::string trap_pts(const G4ThreeVector* pt){
  double dz=pt[7].z(), dy1=(pt[2].y()-pt[1].y())/2, dx1=(pt[1].x()-pt[0].x())/2, dx2=(pt[3].x()-pt[2].x())/2;
  double ta1=(pt[2].x()+pt[3].x()-pt[1].x()-pt[0].x())/(4*dy1);
  double dy2=(pt[6].y()-pt[5].y())/2, dx3=(pt[5].x()-pt[4].x())/2, dx4=(pt[7].x()-pt[6].x())/2;
  double ta2=(pt[6].x()+pt[7].x()-pt[5].x()-pt[4].x())/(4*dy2);
  double tc=(pt[4].x()+dy2*ta2+dx3)/dz, ts=(pt[4].y()+dy2)/dz;
  return trap_spec(dz,std::atan(std::sqrt(tc*tc+ts*ts)),std::atan2(ts,tc),dy1,dx1,dx2,std::atan(ta1),dy2,dx3,dx4,std::atan(ta2)); }
struct G4Trap: G4VSolid { G4Trap(const G4String&n,double dz,double th,double ph,double dy1,double dx1,double dx2,double a1,double dy2,double dx3,double dx4,double a2):G4VSolid(n,trap_spec(dz,th,ph,dy1,dx1,dx2,a1,dy2,dx3,dx4,a2)){}
  G4Trap(const G4String&n,const G4ThreeVector* pt):G4VSolid(n,trap_pts(pt)){}
};
inline std::string para_pts(const G4ThreeVector* pt){
  double dx=(pt[3].x()-pt[2].x())*0.5, dy=(pt[2].y()-pt[1].y())*0.5, dz=pt[7].z();
  double tA=(pt[2].x()+pt[3].x()-pt[1].x()-pt[0].x())*0.25/dy;
  double tc=(pt[4].x()+dy*tA+dx)/dz, ts=(pt[4].y()+dy)/dz;
  return obj("para",{kv("dx",dx),kv("dy",dy),kv("dz",dz),kv("alpha",std::atan(tA)),kv("theta",std::atan(std::sqrt(tc*tc+ts*ts))),kv("phi",std::atan2(ts,tc))}); }
struct G4Para: G4VSolid { G4Para(const G4String&n,const G4ThreeVector* pt):G4VSolid(n,para_pts(pt)){} G4Para(const G4String&n,double a,double b,double c,double d,double e,double f):G4VSolid(n,obj("para",{kv("dx",a),kv("dy",b),kv("dz",c),kv("alpha",d),kv("theta",e),kv("phi",f)})){} };
struct G4Hype: G4VSolid { G4Hype(const G4String&n,double a,double b,double c,double d,double e):G4VSolid(n,obj("hype",{kv("rmin",a),kv("rmax",b),kv("stereo_in",c),kv("stereo_out",d),kv("dz",e)})){} };
struct G4Paraboloid: G4VSolid { G4Paraboloid(const G4String&n,double a,double b,double c):G4VSolid(n,obj("paraboloid",{kv("dz",a),kv("rlo",b),kv("rhi",c)})){} };
struct G4Ellipsoid: G4VSolid { G4Ellipsoid(const G4String&n,double a,double b,double c,double lo=0,double hi=0):G4VSolid(n,obj("ellipsoid",{kv("ax",a),kv("by",b),kv("cz",c),kv("zbottom",lo),kv("ztop",hi)})){} };
struct G4EllipticalTube: G4VSolid { G4EllipticalTube(const G4String&n,double a,double b,double c):G4VSolid(n,obj("eltube",{kv("dx",a),kv("dy",b),kv("dz",c)})){} };
struct G4EllipticalCone: G4VSolid { G4EllipticalCone(const G4String&n,double a,double b,double c,double d):G4VSolid(n,obj("elcone",{kv("xsemi",a),kv("ysemi",b),kv("zheight",c),kv("zcut",d)})){} };
struct G4Tet: G4VSolid { G4Tet(const G4String&n,const G4ThreeVector&a,const G4ThreeVector&b,const G4ThreeVector&c,const G4ThreeVector&d,bool* deg=0):G4VSolid(n,obj("tet",{"\"anchor\":"+vec(a),"\"p2\":"+vec(b),"\"p3\":"+vec(c),"\"p4\":"+vec(d)})){ if(deg)*deg=false; } };
inline std::string pc(const char*t,double s,double d,int nz,const double*z,const double*ri,const double*ro,int ns=-1){ std::string x = obj(t,{kv("sphi",s),kv("dphi",d),"\"z\":"+arr(nz,z),"\"rmin\":"+arr(nz,ri),"\"rmax\":"+arr(nz,ro)}); if(ns>=0){ x.pop_back(); x+=",\"numside\":"+std::to_string(ns)+"}"; } return x; }
inline std::string gpc(const char*t,double s,double d,int n,const double*r,const double*z,int ns=-1){ std::string x = obj(t,{kv("sphi",s),kv("dphi",d),"\"r\":"+arr(n,r),"\"z\":"+arr(n,z)}); if(ns>=0){ x.pop_back(); x+=",\"numside\":"+std::to_string(ns)+"}"; } return x; }
struct G4Polycone: G4VSolid { G4Polycone(const G4String&n,double s,double d,int nz,const double*z,const double*ri,const double*ro):G4VSolid(n,pc("polycone",s,d,nz,z,ri,ro)){}
  G4Polycone(const G4String&n,double s,double d,int nrz,const double*r,const double*z):G4VSolid(n,gpc("genericPolycone",s,d,nrz,r,z)){} };
struct G4Polyhedra: G4VSolid { G4Polyhedra(const G4String&n,double s,double d,int ns,int nz,const double*z,const double*ri,const double*ro):G4VSolid(n,pc("polyhedra",s,d,nz,z,ri,ro,ns)){}
  G4Polyhedra(const G4String&n,double s,double d,int ns,int nrz,const double*r,const double*z):G4VSolid(n,gpc("genericPolyhedra",s,d,nrz,r,z,ns)){} };
inline std::string v2(const std::vector<G4TwoVector>&p){ std::string s="["; for(size_t i=0;i<p.size();i++){ if(i) s+=","; s+="["+num(p[i].dx)+","+num(p[i].dy)+"]";} return s+"]"; }
struct G4GenericTrap: G4VSolid { G4GenericTrap(const G4String&n,double dz,const std::vector<G4TwoVector>&v):G4VSolid(n,obj("genericTrap",{kv("dz",dz),"\"vertices\":"+v2(v)})){} };
struct G4ExtrudedSolid: G4VSolid {
  struct ZSection { double fZ; G4TwoVector fOffset; double fScale; ZSection(double z,const G4TwoVector&o,double s):fZ(z),fOffset(o),fScale(s){} };
  static std::string sec(const std::vector<ZSection>&z){ std::string s="["; for(size_t i=0;i<z.size();i++){ if(i) s+=","; s+="{\"z\":"+num(z[i].fZ)+",\"offset\":["+num(z[i].fOffset.dx)+","+num(z[i].fOffset.dy)+"],\"scale\":"+num(z[i].fScale)+"}";} return s+"]"; }
  G4ExtrudedSolid(const G4String&n,const std::vector<G4TwoVector>&p,const std::vector<ZSection>&z):G4VSolid(n,obj("xtru",{"\"polygon\":"+v2(p),"\"sections\":"+sec(z)})){}
  G4ExtrudedSolid(const G4String&n,const std::vector<G4TwoVector>&p,double hz,const G4TwoVector&o1,double s1,const G4TwoVector&o2,double s2):G4VSolid(n,obj("xtru",{"\"polygon\":"+v2(p),"\"sections\":"+sec({ZSection(-hz,o1,s1),ZSection(hz,o2,s2)})})){} };
inline std::string mat(const G4RotationMatrix&r){ std::string s="["; for(int i=0;i<3;i++){ if(i) s+=","; s+="["+num(r.m[i][0])+","+num(r.m[i][1])+","+num(r.m[i][2])+"]";} return s+"]"; }
inline std::string boolspec(const char*t,const G4VSolid*a,const G4VSolid*b,const G4Transform3D&x){ return std::string("{\"type\":\"")+t+"\",\"a\":"+std::to_string(a->id)+",\"b\":"+std::to_string(b->id)+",\"rotation\":"+mat(x.r)+",\"translation\":"+vec(x.t)+"}"; }
inline G4Transform3D passive(const G4RotationMatrix*r,const G4ThreeVector&t){ G4Transform3D x; if(r) x.r=r->inverse(); x.t=t; return x; }
#define BOOL(C,T) struct C: G4VSolid { C(const G4String&n,G4VSolid*a,G4VSolid*b):G4VSolid(n,boolspec(T,a,b,G4Transform3D())){} \
  C(const G4String&n,G4VSolid*a,G4VSolid*b,G4RotationMatrix*r,const G4ThreeVector&t):G4VSolid(n,boolspec(T,a,b,passive(r,t))){} \
  C(const G4String&n,G4VSolid*a,G4VSolid*b,const G4Transform3D&x):G4VSolid(n,boolspec(T,a,b,x)){} };
BOOL(G4UnionSolid,"union") BOOL(G4SubtractionSolid,"subtraction") BOOL(G4IntersectionSolid,"intersection")
struct G4DisplacedSolid: G4VSolid { G4DisplacedSolid(const G4String&n,G4VSolid*a,G4RotationMatrix*r,const G4ThreeVector&t):G4VSolid(n,"{\"type\":\"displaced\",\"a\":"+std::to_string(a->id)+",\"rotation\":"+mat(passive(r,t).r)+",\"translation\":"+vec(t)+"}"){}
  G4DisplacedSolid(const G4String&n,G4VSolid*a,const G4Transform3D&x):G4VSolid(n,"{\"type\":\"displaced\",\"a\":"+std::to_string(a->id)+",\"rotation\":"+mat(x.r)+",\"translation\":"+vec(x.t)+"}"){} };
