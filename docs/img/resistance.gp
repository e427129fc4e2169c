# Plots of docs/resistance-identification.md from a resistance_compare --trace CSV:
#   gnuplot -e "infile='trace_base.csv'; outfile='docs/img/resistance-base.png'; scen='base'" docs/img/resistance.gp
set terminal pngcairo size 1000,500 font "sans,10"
set datafile separator ","
set yrange [15:75]
set grid
set key top left opaque box
set xlabel "time (h); 8-minute ramp, then 24 h at 21000 r/min"
set ylabel "winding temperature (degC)"
set output outfile
set title sprintf("Simulated TMP drive, scenario %s: true winding temperature and estimates (Han 2019 eq. 3)", scen)
plot infile every ::1 using 1:3 with lines lc rgb "#aaaaaa" title "equation-based", \
     "" every ::1 using 1:4 with lines lc rgb "#e69f00" lw 1.5 title "RLS", \
     "" every ::1 using 1:6 with lines lc rgb "#cc79a7" title "DFRLS (paper)", \
     "" every ::1 using 1:8 with lines lc rgb "#56b4e9" lw 1.5 title "DFRLS on 1 s means", \
     "" every ::1 using 1:7 with lines lc rgb "#009e73" lw 2 title "ours", \
     "" every ::1 using 1:2 with lines lc rgb "black" dt 2 lw 2 title "true"
