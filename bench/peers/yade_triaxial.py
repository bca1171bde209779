# The seed's dense drained triaxial test run in YADE, as a cross-check of demcal's
# triaxial scene with the same contact law and the same protocol.
#
#   yade -n -j1 -x bench/peers/yade_triaxial.py N ETA RATE CSV [SHEAR_DAMPING]
#
# The seed's law (Eqs. 2.3-2.6) is YADE's CohFrictMat with
# Law2_ScGeom6D_CohFrictPhys_CohesionMoment in its incremental form (Belheine et al.
# 2009, the seed's Fig. 2.4): Kr = alphaKr Ks R1 R2, Mp = etaRoll min(R1, R2) |Fn|,
# twisting off (alphaKtw = 0). Differences from demcal, none of which should move
# phi_cv by more than the scatter: YADE's Kn = 2 E R1 R2 / (R1 + R2) grows with the
# grain size (E set so that two 1.5 mm grains meet demcal's Kn = 3e7 N/m), its rolling
# radius is R1 R2 / min(R1, R2) instead of (R1 + R2) / 2, and its walls are YADE boxes
# under TriaxialStressController instead of demcal's servo walls.
#
# Protocol (demcal's dense preparation, bench_triaxial_validation's defaults):
# N grains, diameters uniform in [1, 2] mm, density 2.65e12 kg/m3 (the seed's
# scaling), theta = 0 and no rolling moment, local damping 0.3, isotropic
# compression to 100 p0 then unloading to p0 = 100 kPa; theta = 30 deg and eta set
# on every grain and contact; then the top and bottom walls close at RATE (1/s, true
# strain) with the four lateral walls at p0 and no damping, to eps1 = 0.30.
# Writes eps1, eps_v, sigma1, sigma3, phi_mob, porosity and YADE's unbalanced force
# every 2,000 steps (or every 0.002 of eps1 if sooner); the last line printed is the summary (phi_cv: mean of phi_mob
# over eps1 in [0.20, 0.30]).
import math
import sys
import time

from yade import pack, utils

N = int(sys.argv[1])
ETA = float(sys.argv[2])
RATE = float(sys.argv[3])
CSV = sys.argv[4]
SHEAR_DAMPING = float(sys.argv[5]) if len(sys.argv) > 5 else 0.0
P0, RHO, KN, THETA = 100e3, 2.65e12, 3e7, 30.0
E = KN / 0.75e-3  # Kn = 2 E R1 R2 / (R1 + R2) = E * 0.75 mm for two 1.5 mm grains
L = (N * math.pi / 6 * 3.75e-9 / 0.30) ** (1 / 3.0)  # solid fraction 0.30; <d^3> = 3.75e-9 m3

grains = O.materials.append(CohFrictMat(young=E, poisson=0.9, frictionAngle=0.0, density=RHO,
                                        momentRotationLaw=False, etaRoll=ETA, alphaKr=1.0,
                                        alphaKtw=0.0, isCohesive=False, label='grains'))
O.materials.append(CohFrictMat(young=E, poisson=0.9, frictionAngle=0.0, density=0,
                               momentRotationLaw=False, etaRoll=0.0, alphaKr=0.0, alphaKtw=0.0,
                               isCohesive=False, label='walls'))
lo, hi = Vector3(0, 0, 0), Vector3(L, L, L)
O.bodies.append(utils.aabbWalls([lo, hi], thickness=0, material='walls'))
cloud = pack.SpherePack()
cloud.makeCloud(lo, hi, 0.75e-3, 1.0 / 3.0, N, False, 0.95, seed=1)
O.bodies.append([utils.sphere(c, r, material='grains') for c, r in cloud])

triax = TriaxialStressController(thickness=0, stressMask=7, internalCompaction=False, max_vel=1e-3)
newton = NewtonIntegrator(damping=0.3, gravity=(0, 0, 0))
O.engines = [ForceResetter(),
             InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Box_Aabb()]),
             InteractionLoop([Ig2_Sphere_Sphere_ScGeom6D(), Ig2_Box_Sphere_ScGeom6D()],
                             [Ip2_CohFrictMat_CohFrictMat_CohFrictPhys()],
                             [Law2_ScGeom6D_CohFrictPhys_CohesionMoment(useIncrementalForm=True,
                                                                       always_use_moment_law=True)]),
             triax, newton]
m_min = RHO * math.pi / 6 * 1e-9
O.dt = 0.3 * math.sqrt(m_min / (E * 0.5e-3)) * 0.75  # the smallest pair's Kn; below demcal's step
t0 = time.time()


def settle(goal, budget):
    """Servo all six walls to `goal` until the stress error < 1% and YADE's unbalanced force < 0.01."""
    triax.goal1 = triax.goal2 = triax.goal3 = -goal
    start = O.iter
    while O.iter - start < budget:
        O.run(1000, True)
        if abs(triax.meanStress + goal) < 0.01 * goal and utils.unbalancedForce() < 0.01:
            return True
    return False


ok1 = settle(100 * P0, 200000)
ok2 = settle(P0, 200000)
print('prepared: steps %d, converged %s/%s, porosity %.4f, p %.0f Pa, %.0f s'
      % (O.iter, ok1, ok2, triax.porosity, -triax.meanStress, time.time() - t0), flush=True)

O.materials[grains].frictionAngle = math.radians(THETA)
O.materials[grains].momentRotationLaw = True
for i in O.interactions:
    b1, b2 = O.bodies[i.id1], O.bodies[i.id2]
    if isinstance(b1.shape, Sphere) and isinstance(b2.shape, Sphere):
        r1, r2 = b1.shape.radius, b2.shape.radius
        i.phys.tangensOfFrictionAngle = math.tan(math.radians(THETA))
        i.phys.momentRotationLaw = True
        i.phys.kr = r1 * r2 * i.phys.ks
        i.phys.maxRollPl = ETA * min(r1, r2)
O.run(3000, True)  # stabilise with the new friction, walls still servoed to p0

newton.damping = SHEAR_DAMPING
triax.stressMask = 5  # x and z stress-controlled, y (axial) strain-controlled
triax.goal1 = triax.goal3 = -P0
triax.goal2 = -RATE
h0 = triax.height
v0 = triax.width * triax.height * triax.depth
shear_start = O.iter
rows = []
row_steps = max(10, min(2000, int(0.002 / (RATE * O.dt))))  # a row every <= 0.002 of eps1
with open(CSV, 'w') as out:
    out.write('eps1,eps_v,sigma1,sigma3,phi_mob_deg,porosity,unbalanced\n')
    while True:
        O.run(row_steps, True)
        eps1 = math.log(h0 / triax.height)
        s1 = abs(triax.stress(triax.wall_bottom_id)[1])
        s3 = 0.5 * (abs(triax.stress(triax.wall_left_id)[0]) + abs(triax.stress(triax.wall_back_id)[2]))
        phi = math.degrees(math.asin((s1 - s3) / (s1 + s3)))
        eps_v = 1.0 - triax.width * triax.height * triax.depth / v0  # compression positive
        out.write('%.5f,%.5f,%.1f,%.1f,%.3f,%.4f,%.4g\n' % (eps1, eps_v, s1, s3, phi,
                                                          triax.porosity, utils.unbalancedForce()))
        out.flush()
        rows.append((eps1, phi))
        if eps1 >= 0.30:
            break
cv = [p for e, p in rows if 0.20 <= e <= 0.30]
mean = sum(cv) / len(cv)
sd = math.sqrt(sum((p - mean) ** 2 for p in cv) / (len(cv) - 1)) if len(cv) > 1 else float('nan')
peak = max(rows, key=lambda r: r[1])
print('yade N %d eta %g rate %g shear_damping %g: phi_peak %.2f deg at eps1 %.3f, phi_cv %.2f deg '
      '(sd %.2f over %d rows), shear steps %d, wall %.0f s'
      % (N, ETA, RATE, SHEAR_DAMPING, peak[1], peak[0], mean, sd, len(cv), O.iter - shear_start,
         time.time() - t0), flush=True)
