MODULE MainModule
  PERS tooldata tGripper:=[TRUE,[[12,-30,180],[0.9987503,0,0.0499792,0]],[2.5,[0,0,80],[1,0,0,0],0,0,0]];
  TASK PERS wobjdata wTable:=[FALSE,TRUE,"",[[-350,-300,50],[0.9689124,0,0,0.2474040]],[[40,25,10],[0.9887711,0.0099,0,-0.1494381]]];
  CONST robtarget p10:=[[100.5,-20,300],[0,0.7071068,0.7071068,0],[0,-1,1,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
  CONST jointtarget jHome:=[[0,-30,30,0,45,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    MoveAbsJ jHome\NoEOffs, v1000, z50, tGripper;
    MoveL p10, v500, z10, tGripper\WObj:=wTable;
    MoveJ [[110,-20,300],[0,0.7071068,0.7071068,0],[0,-1,1,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v500, fine, tGripper\WObj:=wTable;
    MoveC p10, [[120,-20,300],[0,1,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, z5, tGripper\WObj:=wTable;
    MoveL Offs(p10, 0, 0, 50), v200, z10, tGripper\WObj:=wTable;
    TriggL p10, v500, gunon, fine, tGripper;
  ENDPROC
ENDMODULE
