#!/usr/bin/env python3
"""Decomposes tube pose errors by viewing geometry (diagnostics for tubeloc refine).

For each estimate matched to the nearest true tube of its image (within 50 mm; truths with
visible_fraction >= 0.5), prints medians / p90 of: the axis angle, the centre's distance to the
true axis (perp), its error along the true viewing ray (|ray|, depth) and across it (lat), the
axis tilt error toward the camera (tilt) and the axis error in the image plane (inplane).
Usage: pose_decompose.py annotations.json poses.json [poses.json ...]   (numpy)
"""
import json,sys,numpy as np
gt=json.load(open(sys.argv[1]))
anns={}
for a in gt['annotations']:
    if a.get('visible_fraction',1)<0.5 or 'T_cam_tube' not in a: continue
    T=a['T_cam_tube'];R=np.array(T['rotation']);anns.setdefault(a['image_id'],[]).append((np.array(T['translation']),R[:,2],a['id']))
for f in sys.argv[2:]:
    P=json.load(open(f))
    rows=[]
    for p in P:
        c=np.array(p['centre']);ax=np.array(p.get('end_direction',p.get('axis')));ax/=np.linalg.norm(ax)
        best=min(anns.get(p['image_id'],[]),key=lambda g:np.linalg.norm(g[0]-c),default=None)
        if best is None or np.linalg.norm(best[0]-c)>0.05: continue
        t,a,_=best
        ray=t/np.linalg.norm(t)
        d=c-t
        along_ray=d@ray
        lat=np.linalg.norm(d-ray*along_ray)
        # perp error to true axis
        perp=np.linalg.norm(d-a*(d@a))
        if ax@a<0: ax=-ax
        ang=np.degrees(np.arccos(min(1,abs(ax@a))))
        # out of plane: tilt toward camera = asin(a.ray) difference
        tilt=np.degrees(np.arcsin(ax@ray)-np.arcsin(a@ray))
        # in-image: angle of components perpendicular to ray
        def proj(v): v=v-ray*(v@ray); return v/np.linalg.norm(v)
        inpl=np.degrees(np.arccos(min(1,abs(proj(ax)@proj(a)))))
        rows.append((ang,perp*1e3,along_ray*1e3,lat*1e3,abs(tilt),inpl,p['converged']))
    r=np.array(rows)
    med=lambda x: np.median(x); p90=lambda x: np.percentile(x,90)
    print(f"{f}: n={len(r)} conv={int(r[:,6].sum())} axis {med(r[:,0]):.2f}/{p90(r[:,0]):.2f} perp {med(r[:,1]):.2f}/{p90(r[:,1]):.2f} |ray| {med(abs(r[:,2])):.2f}/{p90(abs(r[:,2])):.2f} (signed med {med(r[:,2]):+.2f}) lat {med(r[:,3]):.2f}/{p90(r[:,3]):.2f} tilt {med(r[:,4]):.2f}/{p90(r[:,4]):.2f} inplane {med(r[:,5]):.2f}/{p90(r[:,5]):.2f}")
