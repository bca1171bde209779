"""Opens a task's snapshots in ParaView as a user would: the .xmf with the XDMF reader
and the .h5 (through a .h5part link) with the H5Part reader. Both must give every
grain at every snapshot time, and the XDMF reader's velocity and spin vectors must be
the H5Part reader's vx vy vz and wx wy wz. Run by paraview_snapshots.sh under pvpython."""
import sys

from paraview import servermanager as sm
from paraview.simple import H5PartReader, XDMFReader

xmf, h5part, grains = sys.argv[1], sys.argv[2], int(sys.argv[3])


def arrays(reader, t):
    reader.UpdatePipeline(t)
    d = sm.Fetch(reader)
    if d.IsA("vtkMultiBlockDataSet"):
        d = d.GetBlock(0)
    pd = d.GetPointData()
    return d.GetNumberOfPoints(), {pd.GetArray(i).GetName(): pd.GetArray(i) for i in range(pd.GetNumberOfArrays())}


def fail(msg):
    print("FAIL:", msg)
    sys.exit(1)


x = XDMFReader(FileNames=[xmf])
x.UpdatePipelineInformation()
h = H5PartReader(FileName=h5part)
h.UpdatePipelineInformation()
times = list(x.TimestepValues)
if len(times) < 2 or times != list(h.TimestepValues):
    fail("snapshot times differ: xdmf %s, h5part %s" % (times, list(h.TimestepValues)))
for t in times:
    nx, ax = arrays(x, t)
    nh, ah = arrays(h, t)
    if nx != grains or nh != grains:
        fail("t=%g: %d grains through xdmf, %d through h5part, job has %d" % (t, nx, nh, grains))
    for vec, parts in (("velocity", "vx vy vz"), ("spin", "wx wy wz")):
        if vec not in ax or ax[vec].GetNumberOfComponents() != 3:
            fail("t=%g: no 3-component %s through xdmf (arrays %s)" % (t, vec, sorted(ax)))
        for c, name in enumerate(parts.split()):
            for i in range(grains):
                if ax[vec].GetComponent(i, c) != ah[name].GetValue(i):
                    fail("t=%g: %s[%d][%d] != %s[%d]" % (t, vec, i, c, name, i))
    for scalar in ("radius", "fixed"):
        if scalar not in ax:
            fail("t=%g: no %s through xdmf" % (t, scalar))
print("ok: %d snapshots of %d grains, times %s" % (len(times), grains, times))
